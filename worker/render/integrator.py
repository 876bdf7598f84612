"""``hg_path``: a spectral path tracer that carries the coherence of light in Hermite-Gauss space.

Estimator. Unidirectional path tracing from the camera with next-event estimation and MIS (balance
heuristic; hero-wavelength MIS per path, Wilkie et al. 2014 §4, docs/integrator.md) and Russian roulette,
both depths in Mitsuba's convention (``max_depth`` 1 = emitters seen directly, 2 = direct illumination;
``rr_depth`` 1 = roulette may end a path at the camera-visible surface, as Mitsuba's ``path``). As in
prb.py the roulette's survival probability is min(max β·η², 0.95), η the product of the refractions'
relative indices, so the radiance factors 1/η² of refraction are not mistaken for absorption. Emitter
surfaces absorb. ``trace`` reads like Mitsuba's prb.py: its loop state is declared together (the
``loop_struct`` classes below) and banner comments mark the phases of a bounce.

Coherence state (paper §5.2: "each traced ray carries the shape matrix, transverse HG coefficients, the
propagation direction and distance r"). Because paths start at the camera, the coherence of the light a
vertex *receives* is known only once the path reaches that light's source. So each non-specular vertex
leaves a *pending* record, resolved at the next non-specular vertex or emitter hit:

* ``chain_distance_m`` r: the distance accumulated along perfect mirror/glass chains since the pending
  vertex (Θ is kept and r grows through Dirac interactions — §5 "Perfectly specular reflectors");
* ``frame_x``/``frame_y``: the transverse frame of the pending vertex's incident beam, reflected through
  the chain so that the source's Σ⊥ lands in that vertex's frame;
* ``PendingCoating``: for a thin-film vertex, the film shear s (m) between successive beams
  (``hgcore.optics.thin_film.film_shear``, 2τ tan θ_t in the plane of incidence), also carried through the
  chain, its partially-coherent reflectance terms (linear in the visibilities), and what it passes on
  towards the pixel (its acceptance: one direction for its specular part, its lobe's width otherwise).

At resolution the source is the emitter (whole emitter, BRIEF) or a non-specular surface: a *secondary*
incoherent source whose extent is the part of that surface that is lit and seen from the receiver (van
Cittert–Zernike, docs/physics.md §7). Its points are mutually incoherent, so each path, which reaches one
point of it, carries a point source (Σ⊥ = 0, phase along the sampled direction); averaging the paths
gives the partially coherent response of the part of the lit patch the pixel sees. A material's explicit
``scattering_region_radius_m`` overrides this with a uniform disk of that radius in its tangent plane.
The environment (light from infinity in every direction, reached by rays that leave the scene) is treated
the same way: a plane wave from the path's direction per path, van Cittert–Zernike over the paths
(docs/physics.md §9). Textured material parameters are read at each vertex before its branches
(``VertexSpectra``), so the coherence maths sees their local values (a film's local thickness sets its shear
and phase).

What a pixel sees (docs/physics_interactions.md §3): a film evaluates each plane wave of an incoherent
source coherently, so a pixel sees its fringes averaged over the source directions the film (and the
camera's lens, whose cone the paths sample) pass towards it. ``_film_factor`` and the film's next-event
evaluation combine the source with the film's acceptance (``bsdfs.thin_film.detected_light``) and take the
film's phase at the mean direction of what reaches the pixel; beyond a non-specular vertex the whole source
does (the paper's Eq. 18).

Diagnostics (BRIEF): M = (k/r)²Σ⊥ at λ = 550 nm of the light incident at the first non-specular vertex,
luminance-weighted over the pixel's paths: next-event contributions there use the emitter's Σ⊥, light
from emitters hit by BSDF sampling the emitter's Σ⊥, light from secondary sources the VCZ estimate of
``output.secondary_source_m``: the luminance-weighted covariance of the directions the pixel's paths
receive it from (per-sample sums ``vcz_*``).
"""

from __future__ import annotations

import typing
from dataclasses import dataclass, field, fields
from typing import NamedTuple

import drjit as dr

from hgcore.artifacts.layout import K_REFERENCE_PER_M, BandLayout
from hgcore.optics import sources
from hgcore.optics.frames import transverse_frame_components
from hgcore.optics.thin_film import film_shear
from worker.mitsuba_setup import configured_mitsuba
from worker.render import materials as mat
from worker.render.bsdfs import (
    IncidentCoherence,
    MaterialKernels,
    MaterialParams,
    MaterialSample,
    VertexSpectra,
    VisibilityModel,
)
from worker.render.bsdfs.lobes import mean_over_wavelengths
from worker.render.bsdfs.thin_film import (
    DetectedLight,
    detected_light,
    film_at_directions,
    visible_reflectance,
)
from worker.render.drjit_ops import drjit_ops
from worker.render.emitters import (
    FAR_DISTANCE_M,
    CylinderModes,
    EmitterKind,
    emitter_coherence,
    emitter_direction,
    emitter_is_environment,
    emitter_is_rect,
    emitter_rect_modes,
    sphere_solid_angle,
)
from worker.render.spectral import cie1931_xyz
from worker.render.textures import TextureKernels
from worker.render.wavelength_sampling import lane_weights

# Python integrators subclass variant-specific classes: the process's entry point chose the variant before
# this import (``worker.mitsuba_setup.configure_mitsuba``, from its settings); importing changes nothing.
mi = configured_mitsuba()
OPS = drjit_ops()

T = typing.TypeVar("T")


def loop_struct(cls: type[T]) -> type[T]:
    """A dataclass that Dr.Jit traverses as one piece of symbolic-loop state (``DRJIT_STRUCT`` from the
    field types); every field has a default, the state's value before the first bounce."""
    cls = dataclass(cls)
    hints = typing.get_type_hints(cls)
    cls.DRJIT_STRUCT = {f.name: typing.get_origin(hints[f.name]) or hints[f.name] for f in fields(cls)}
    return cls


@dataclass
class RenderContext:
    """Everything ``hg_path`` needs besides the Mitsuba scene (built by ``scene_compiler``)."""

    bands: BandLayout
    material_table: mat.MaterialTable
    material_flat: mi.Float
    spectra_flat: mi.Float
    shape_material: mi.UInt32  # shape registry id -> material index
    emitter_flat: mi.Float
    emitter_index: mi.UInt32  # emitter registry id -> emitter row
    emitter_kinds: set
    # (n, m) -> ĉ of the universal expansions (Eq. 14) used for visibilities: uniform disks (spheres, disks,
    # scattering regions) and uniform rectangles (rectangles; cylinders: ``cylinder_modes`` where it is set).
    disk_coefficients: dict[tuple[int, int], float]
    rect_coefficients: dict[tuple[int, int], float]
    black_material: int  # index of the absorbing material (emitters, misses)
    rect_sources: bool  # whether any emitter is a rectangle or a cylinder
    camera_position: mi.Point3f  # world-space centre of projection
    camera_right: mi.Vector3f  # world-space unit vectors of the image's +x and +y (up) directions
    camera_up: mi.Vector3f
    cie1931: mi.Float  # Mitsuba's CIE 1931 table as an array of our own (``spectral.cie1931_table``)
    # The open cylinders' view-dependent modes (None: no cylinder, or one mode).
    cylinder_modes: CylinderModes | None = None
    # The scene's texture lookups (None: no material reads a texture; their tables are the materials').
    textures: TextureKernels | None = None

    def kernel_tables(self) -> list[typing.Any]:
        """The arrays of this context that kernels read (what a frozen pass names as inputs)."""
        tables = [
            self.material_flat,
            self.spectra_flat,
            self.shape_material,
            self.emitter_flat,
            self.emitter_index,
            self.camera_position,
            self.camera_right,
            self.camera_up,
            self.cie1931,
        ]
        if self.cylinder_modes is not None:
            tables.append(self.cylinder_modes.values)
        return tables


@dataclass
class PathResult:
    radiance: mi.Spectrum  # at the sample's wavelengths
    diag_weight: mi.Float
    diag_mxx: mi.Float
    diag_mxy: mi.Float
    diag_myy: mi.Float
    diag_r: mi.Float
    diag_cos2: mi.Float
    diag_sin2: mi.Float
    # Light from secondary sources (non-specular surfaces without a region override): its luminance, that
    # times r, and the direction (camera coordinates: right, up, forward) it arrives from at the first vertex.
    vcz_weight: mi.Float
    vcz_r: mi.Float
    vcz_direction: mi.Vector3f
    # Environment light that next-event estimation brings to the first vertex: its luminance and the
    # direction (camera coordinates) it arrives from, another VCZ sample of the path (zero without one).
    vcz_direct_weight: mi.Float
    vcz_direct_direction: mi.Vector3f
    depth_m: mi.Float
    normal: mi.Vector3f
    albedo: mi.Spectrum


# ---------------------------------------------------------------------------------------- loop state
@loop_struct
class PathState:
    """The estimator's state (as prb.py's loop variables)."""

    L: mi.Spectrum = field(default_factory=lambda: mi.Spectrum(0.0))  # radiance accumulator
    beta: mi.Spectrum = field(default_factory=lambda: mi.Spectrum(1.0))  # path throughput
    # Product of the relative indices η of the refractions so far: β·η² is the throughput without the
    # radiance factors 1/η², which Russian roulette must not mistake for absorption (prb.py).
    eta: mi.Float = field(default_factory=lambda: mi.Float(1.0))
    # Path-level hero-wavelength MIS (docs/integrator.md): ρ_k = r_k/mean_h r_h, where
    # r_k = Π_v p_k(v)/Π_v p_hero(v) is the path's density had λ_k been the hero relative to the hero's own.
    hero_ratio: mi.Spectrum = field(default_factory=lambda: mi.Spectrum(1.0))
    depth: mi.UInt32 = field(default_factory=lambda: mi.UInt32(0))
    # the previous vertex, for MIS of emission reached by material sampling: its position, normal, time
    # and wavelengths (what Mitsuba's emitter densities read; the whole SurfaceInteraction3f would be
    # 40 more floats of loop state)
    prev_si: mi.Interaction3f = field(default_factory=lambda: dr.zeros(mi.Interaction3f))
    prev_pdf: mi.Float = field(default_factory=lambda: mi.Float(1.0))
    prev_delta: mi.Bool = field(default_factory=lambda: mi.Bool(True))
    prev_skip_emission: mi.Bool = field(default_factory=lambda: mi.Bool(False))  # NEE-only lobes


@loop_struct
class PendingVertex:
    """A non-specular vertex waiting for the coherence of the light it receives (module docstring)."""

    pending: mi.Bool = field(default_factory=lambda: mi.Bool(False))
    first: mi.Bool = field(default_factory=lambda: mi.Bool(False))  # it is the pixel's first such vertex
    # r: metres since that vertex, accumulated through perfect mirrors and refractions
    chain_distance: mi.Float = field(default_factory=lambda: mi.Float(0.0))
    # transverse frame of that vertex's incident beam, reflected through the specular chain
    frame_x: mi.Vector3f = field(default_factory=lambda: mi.Vector3f(0.0))
    frame_y: mi.Vector3f = field(default_factory=lambda: mi.Vector3f(0.0))


@loop_struct
class PendingCoating:
    """The thin-film coating of a pending vertex (Eq. 18): its value waits for the resolved coherence."""

    pending: mi.Bool = field(default_factory=lambda: mi.Bool(False))
    transmitted: mi.Bool = field(default_factory=lambda: mi.Bool(False))
    # the film shear s (m) between successive beams, carried through the specular chain like the frame
    separation: mi.Vector3f = field(default_factory=lambda: mi.Vector3f(0.0))
    material: mi.UInt32 = field(default_factory=lambda: mi.UInt32(0))
    # The film normal's components (n·x, n·y, n·k) in the record's frame (x, y) and sampled incident
    # direction k: the chain maps all three alike, so they hold at the source's end too.
    normal: mi.Vector3f = field(default_factory=lambda: mi.Vector3f(0.0, 0.0, -1.0))
    # The film's acceptance (``bsdfs.thin_film.detected_light``): the centre of its lobe relative to k (rad,
    # in the record's frame) and its per-axis variance per wavelength (rad²; 0: the specular part or
    # transmission, which pass one direction).
    acceptance_mean: mi.Point2f = field(default_factory=lambda: mi.Point2f(0.0))
    lobe_variance: mi.Spectrum = field(default_factory=lambda: mi.Spectrum(0.0))
    thickness: mi.Float = field(default_factory=lambda: mi.Float(0.0))  # τ (m) there (a texture's)
    # [R_incoherent, X_1 …] at the sampled direction (linear in the visibilities V_d); none without films
    terms: list[mi.Spectrum] = field(default_factory=list)


@loop_struct
class CoherenceSample:
    """What the diagnostics record of light reaching the first non-specular vertex (BRIEF): M = (k/r)²Σ⊥
    at λ = 550 nm in that vertex's incident frame, r (m), (cos 2ψ, sin 2ψ) of the ℓ₁ axis on screen;
    ``secondary``: from a secondary source, whose M comes from the spread of arrival directions (VCZ).
    As a sum (``DiagnosticSums.moments``) the same fields hold Σw·M, Σw·r, Σw·(cos 2ψ, sin 2ψ)."""

    m_xx: mi.Float = field(default_factory=lambda: mi.Float(0.0))
    m_xy: mi.Float = field(default_factory=lambda: mi.Float(0.0))
    m_yy: mi.Float = field(default_factory=lambda: mi.Float(0.0))
    r: mi.Float = field(default_factory=lambda: mi.Float(0.0))
    cos2: mi.Float = field(default_factory=lambda: mi.Float(0.0))
    sin2: mi.Float = field(default_factory=lambda: mi.Float(0.0))
    secondary: mi.Bool = field(default_factory=lambda: mi.Bool(False))

    def accumulate(self, weight: mi.Float, sample: CoherenceSample) -> None:
        """Add ``weight`` × ``sample`` to these sums."""
        self.m_xx += weight * sample.m_xx
        self.m_xy += weight * sample.m_xy
        self.m_yy += weight * sample.m_yy
        self.r += weight * sample.r
        self.cos2 += weight * sample.cos2
        self.sin2 += weight * sample.sin2


@loop_struct
class FirstVertex:
    """The pixel's first non-specular vertex, whose incident coherence the diagnostics report."""

    seen: mi.Bool = field(default_factory=lambda: mi.Bool(False))  # the path has passed it
    frame_x: mi.Vector3f = field(default_factory=lambda: mi.Vector3f(0.0))  # its incident frame
    frame_y: mi.Vector3f = field(default_factory=lambda: mi.Vector3f(0.0))
    direction: mi.Vector3f = field(default_factory=lambda: mi.Vector3f(0.0, 0.0, 1.0))  # sampled from it
    indirect_ready: mi.Bool = field(default_factory=lambda: mi.Bool(False))  # its record is resolved
    indirect: CoherenceSample = field(default_factory=CoherenceSample)  # … to this


@loop_struct
class DiagnosticSums:
    """Luminance-weighted per-sample sums of the coherence diagnostics (BRIEF; the renderer's ``diag_*``
    and ``vcz_*``): Σw and the ``moments`` Σw·M, Σw·r, Σw·(cos 2ψ, sin 2ψ); light from secondary sources
    goes to Σw_vcz and Σw_vcz·r instead."""

    weight: mi.Float = field(default_factory=lambda: mi.Float(0.0))
    moments: CoherenceSample = field(default_factory=CoherenceSample)
    vcz_weight: mi.Float = field(default_factory=lambda: mi.Float(0.0))
    vcz_r: mi.Float = field(default_factory=lambda: mi.Float(0.0))
    # environment light by NEE at the first vertex (at most one per path): luminance, arrival direction
    vcz_direct_weight: mi.Float = field(default_factory=lambda: mi.Float(0.0))
    vcz_direct_direction: mi.Vector3f = field(default_factory=lambda: mi.Vector3f(0.0, 0.0, 1.0))

    def add(self, weight: mi.Float, sample: CoherenceSample) -> None:
        """Count light of luminance ``weight`` (0 in lanes that do not count) described by ``sample``."""
        vcz = dr.select(sample.secondary, weight, 0.0)
        w = dr.select(sample.secondary, 0.0, weight)
        self.vcz_weight += vcz
        self.vcz_r += vcz * sample.r
        self.weight += w
        self.moments.accumulate(w, sample)


@loop_struct
class FirstHit:
    """AOVs of the camera-visible surface."""

    depth_m: mi.Float = field(default_factory=lambda: mi.Float(0.0))  # from the centre of projection
    normal: mi.Vector3f = field(default_factory=lambda: mi.Vector3f(0.0))
    material: mi.UInt32 = field(default_factory=lambda: mi.UInt32(0))
    # its texture coordinates (kept where textures vary the albedo; read after the loop)
    uv: mi.Point2f = field(default_factory=lambda: mi.Point2f(0.0))


class Vertex(NamedTuple):
    """The bounce's surface as the coherence bookkeeping reads it (one per loop iteration)."""

    si: mi.SurfaceInteraction3f
    material: mi.UInt32
    kind: mi.UInt32
    spectra: VertexSpectra  # the material's spectra at the path's wavelengths, looked up once per bounce
    frame: mi.Frame3f  # shading frame, flipped towards the incident side where two-sided
    hit_emitter: mi.Bool
    specular: mi.Bool
    nonspecular: mi.Bool


def mis_weight(pdf_a: mi.Float, pdf_b: mi.Float) -> mi.Float:
    """Balance heuristic p_a/(p_a + p_b) of the strategy with density ``pdf_a`` (hero-MIS densities)."""
    return pdf_a / dr.maximum(pdf_a + pdf_b, 1e-20)


def roulette_applies(vertex_index: mi.UInt32, rr_depth: int) -> mi.Bool:
    """Whether Russian roulette may end a path at its vertex ``vertex_index`` (0: the camera-visible
    surface). Depths count as ``max_depth`` does, vertex i at depth i + 1, so ``rr_depth`` = 1 lets
    roulette end a path at the camera-visible surface: the meaning Mitsuba documents and its C++ ``path``
    implements (prb.py starts one vertex later, at depth ``rr_depth`` + 1)."""
    return vertex_index + 1 >= rr_depth


def _luminance(y_weights: list[mi.Float], value: mi.Spectrum) -> mi.Float:
    """Y of a four-wavelength spectral estimate: Σ_j w_j·value_j with w_j = ω_j·ȳ(λ_j) (CIE 1931 ȳ),
    ω_j = 1/(4 p(λ_j)) the lane's weight (``wavelength_sampling.lane_weights``; Λ/4 when uniform)."""
    total = mi.Float(0.0)
    for j in range(len(y_weights)):
        total += y_weights[j] * value[j]
    return total


def _reflect_vector(vector: mi.Vector3f, normal: mi.Vector3f) -> mi.Vector3f:
    """Mirror image of a (free) vector in the plane with unit ``normal``."""
    return vector - 2.0 * dr.dot(vector, normal) * normal


class HGPathIntegrator(mi.SamplingIntegrator):
    """Mitsuba plugin ``hg_path`` (properties: ``max_depth`` = 8, ``rr_depth`` = 5)."""

    #: False: sources carry their shape matrix and coherence-sensitive terms take the phase towards the
    #: emitter's centre (PLT). True: every source is a point at the sampled position — a fully coherent
    #: plane wave per sample, Σ⊥ = 0 — the radiometric baseline of ``worker.render.rlt``.
    plane_waves: bool = False

    def __init__(self, props: mi.Properties) -> None:
        super().__init__(props)
        self.max_depth = int(props.get("max_depth", 8))
        self.rr_depth = int(props.get("rr_depth", 5))
        self.context: RenderContext | None = None
        self.kernels: MaterialKernels | None = None

    def attach(self, context: RenderContext) -> None:
        self.context = context
        visibility = VisibilityModel(
            context.disk_coefficients, context.rect_coefficients, bool(context.rect_sources)
        )
        params = MaterialParams(
            context.material_flat, context.spectra_flat, context.material_table, visibility, context.textures
        )
        self.kernels = MaterialKernels(params)

    # ------------------------------------------------------------------ coherence helpers
    def _rect_modes(self, emitter_row: mi.UInt32, frame_x: mi.Vector3f, frame_y: mi.Vector3f):
        """Per-lane ĉ of rectangle-like emitters seen in this frame (``emitters.emitter_rect_modes``)."""
        table, modes = self.context.emitter_flat, self.context.cylinder_modes
        return emitter_rect_modes(mi, table, modes, emitter_row, frame_x, frame_y)

    def _frame_for(self, direction: mi.Vector3f) -> tuple[mi.Vector3f, mi.Vector3f]:
        x_axis, y_axis = transverse_frame_components(
            (direction.x, direction.y, direction.z), tuple(self.context.camera_right), OPS
        )
        return mi.Vector3f(*x_axis), mi.Vector3f(*y_axis)

    def _scattering_region(
        self, material: mi.UInt32, normal: mi.Vector3f, frame_x: mi.Vector3f, frame_y: mi.Vector3f
    ) -> tuple[tuple[mi.Float, mi.Float, mi.Float], mi.Bool]:
        """(Σ⊥, overridden) of the secondary source a path reaches at a non-specular vertex, in the frame ⟂
        to the direction it is seen along.

        Without an override the path carries one point of the lit patch (Σ⊥ = 0; the patch's extent comes
        from averaging paths, module docstring); with ``scattering_region_radius_m`` a uniform disk of that
        radius in the tangent plane (the projection depends on the frame only).
        """
        radius = self.kernels.param(material, mat.SCATTERING_REGION_RADIUS_M)
        sigma = sources.disk_covariance_components(
            radius,
            (normal.x, normal.y, normal.z),
            (frame_x.x, frame_x.y, frame_x.z),
            (frame_y.x, frame_y.y, frame_y.z),
        )
        return sigma, radius > 0.0

    def _camera_coordinates(self, direction: mi.Vector3f) -> mi.Vector3f:
        """``direction`` in the camera's (right, up, forward) basis (orthonormal: covariances are kept)."""
        context = self.context
        forward = dr.cross(context.camera_right, context.camera_up)
        return mi.Vector3f(
            dr.dot(direction, context.camera_right),
            dr.dot(direction, context.camera_up),
            dr.dot(direction, forward),
        )

    def _emitter_lookup(self, emitter_ptr: mi.EmitterPtr) -> mi.UInt32:
        registry_id = dr.reinterpret_array(mi.UInt32, emitter_ptr)
        return dr.gather(mi.UInt32, self.context.emitter_index, registry_id)

    def _has_environment(self) -> bool:
        """Whether the scene has an environment emitter (decided when the kernel is traced): only then do
        rays that leave the scene reach an emitter."""
        return EmitterKind.ENVIRONMENT in self.context.emitter_kinds

    def _is_environment(self, emitter_row: mi.UInt32) -> mi.Bool:
        """Lanes whose emitter is the environment (always False in scenes without one)."""
        if not self._has_environment():
            return mi.Bool(False)
        return emitter_is_environment(mi, self.context.emitter_flat, emitter_row)

    def _film_thickness_textured(self) -> bool:
        """Whether a film's thickness comes from a texture (the pending film then carries its local τ)."""
        return mat.FILM_THICKNESS_M in self.kernels.params.textured

    def _has_sphere_emitters(self) -> bool:
        """Whether the scene has a sphere emitter (decided when the kernel is traced): without one the
        stable cone density and its NEE weight (``_emitter_pdf``) would select Mitsuba's in every lane, at
        the cost of their table reads and an emitter ``eval_direction`` virtual call per bounce."""
        return EmitterKind.SPHERE in self.context.emitter_kinds

    def _emitter_pdf(
        self, scene: mi.Scene, mitsuba_pdf: mi.Float, emitter_row: mi.UInt32, distance_m: mi.Float | None
    ) -> mi.Float:
        """The solid-angle density of emitter sampling towards emitter ``emitter_row`` from a receiver
        ``distance_m`` from its centre: Mitsuba's, except for spheres seen from outside, whose uniform cone
        has the density selection/Ω with Ω from ``emitters.sphere_solid_angle`` (Mitsuba's float32 cone
        pdf is 3 % high for a 1 mm sphere at 0.6 m and infinite below a/d ≈ 2.4e-4)."""
        if not self._has_sphere_emitters():
            return mitsuba_pdf  # (the select below would take Mitsuba's in every lane)
        sphere, solid_angle = sphere_solid_angle(mi, self.context.emitter_flat, emitter_row, distance_m)
        selection = scene.pdf_emitter(emitter_row, sphere)
        return dr.select(sphere, selection / dr.maximum(solid_angle, 1e-30), mitsuba_pdf)

    def _screen_angle_terms(
        self, sxx: mi.Float, sxy: mi.Float, syy: mi.Float, frame_x: mi.Vector3f, frame_y: mi.Vector3f
    ) -> tuple[mi.Float, mi.Float]:
        """(cos 2ψ, sin 2ψ) of the screen-space angle ψ of the ℓ₁ axis (smallest eigenvalue of Σ⊥).

        Algebraic throughout (no trigonometry in the kernel): the ℓ₁ axis of [[a, b], [b, c]] has doubled
        angle 2φ with (cos 2φ, sin 2φ) = −(a − c, 2b)/h, h = √((a − c)² + 4b²); half-angle formulas give
        the axis (cos φ, sin φ); its screen projection (X, Y) gives cos 2ψ = (X² − Y²)/(X² + Y²) and
        sin 2ψ = 2XY/(X² + Y²). An isotropic Σ⊥ has no axis and contributes (0, 0).
        """
        difference = sxx - syy
        h = dr.sqrt(dr.square(difference) + 4.0 * dr.square(sxy))
        isotropic = h <= 1e-6 * (sxx + syy)
        safe_h = dr.select(isotropic, 1.0, h)
        cos_2phi = -difference / safe_h
        sin_2phi = -2.0 * sxy / safe_h
        cos_phi = dr.sqrt(dr.maximum(0.5 * (1.0 + cos_2phi), 0.0))
        sin_phi = dr.mulsign(dr.sqrt(dr.maximum(0.5 * (1.0 - cos_2phi), 0.0)), sin_2phi)
        axis = frame_x * cos_phi + frame_y * sin_phi
        x = dr.dot(axis, self.context.camera_right)
        y = dr.dot(axis, self.context.camera_up)
        norm2 = dr.maximum(x * x + y * y, 1e-20)
        return (
            dr.select(isotropic, 0.0, (x * x - y * y) / norm2),
            dr.select(isotropic, 0.0, 2.0 * x * y / norm2),
        )

    def _coherence_sample(
        self,
        sigma: tuple[mi.Float, mi.Float, mi.Float],
        distance_m: mi.Float,
        angle_terms: tuple[mi.Float, mi.Float],
        secondary: mi.Bool | bool = False,
    ) -> CoherenceSample:
        """The diagnostics' record of light with Σ⊥ ``sigma`` after r = ``distance_m`` (m), whose ℓ₁ axis
        has the screen angle terms ``angle_terms`` (``_screen_angle_terms``)."""
        scale2 = dr.square(K_REFERENCE_PER_M / dr.maximum(distance_m, 1e-9))
        return CoherenceSample(
            scale2 * sigma[0],
            scale2 * sigma[1],
            scale2 * sigma[2],
            distance_m,
            *angle_terms,
            mi.Bool(secondary),
        )

    def _resolve(
        self,
        resolve: mi.Bool,
        vertex: Vertex,
        emitter_row: mi.UInt32,
        segment: mi.Float,
        ray: mi.Ray3f,
        wavelengths: mi.Spectrum,
        path: PathState,
        record: PendingVertex,
        coating: PendingCoating,
        first_vertex: FirstVertex,
    ) -> None:
        """Resolve the pending record in the lanes ``resolve``: its source is what the path reached — the
        emitter hit (its whole silhouette, from its centre) or a non-specular surface (a secondary source:
        one point, or its scattering region) — seen in the record's frame after r = ``chain_distance``. A
        pending film's throughput is rescaled by R(V)/R_incoherent; the pixel's first record becomes the
        diagnostics' ``first_vertex.indirect``."""
        em_sigma = emitter_coherence(
            mi,
            self.context.emitter_flat,
            self.context.emitter_kinds,
            emitter_row,
            record.frame_x,
            record.frame_y,
        )
        region_sigma, overridden = self._scattering_region(
            vertex.material, vertex.si.n, record.frame_x, record.frame_y
        )
        source_sigma = dr.select(vertex.hit_emitter, tuple(em_sigma), tuple(region_sigma))
        if self.plane_waves:
            source_sigma = (mi.Float(0.0), mi.Float(0.0), mi.Float(0.0))
        # An emitter's coherence propagates from its centre (as in NEE): the last segment's length
        # becomes the distance from the segment's origin to that centre.
        centre_distance, from_centre = emitter_direction(mi, self.context.emitter_flat, emitter_row, ray.o)
        record.chain_distance = dr.select(
            vertex.hit_emitter, record.chain_distance - segment + centre_distance, record.chain_distance
        )
        # The environment is a plane wave from the path's direction (Σ⊥ = 0, like one point of a secondary
        # source: the paths' directions sample its van Cittert–Zernike coherence), from "infinitely" far.
        environment = vertex.hit_emitter & self._is_environment(emitter_row)
        if self._has_environment():
            record.chain_distance = dr.select(
                environment, record.chain_distance - segment + FAR_DISTANCE_M, record.chain_distance
            )
        resolved = IncidentCoherence(
            *source_sigma,
            record.chain_distance,
            record.frame_x,
            record.frame_y,
            vertex.hit_emitter & emitter_is_rect(mi, self.context.emitter_flat, emitter_row),
            self._rect_modes(emitter_row, record.frame_x, record.frame_y),
        )
        if self.kernels.has(mat.INTERFERENCE_KINDS):
            # A symbolic branch: most resolved records are not a film's (the diffuse floor's), and packets
            # without a film lane skip the visibilities of every beam.
            def film_factor(beta: mi.Spectrum) -> mi.Spectrum:
                # The emitter's centre seen along the chain: its offset Δ ⟂ the last segment, over the
                # unfolded distance r, is the centre's direction relative to the path at the film.
                to_centre = -centre_distance * from_centre
                across = to_centre - dr.dot(to_centre, ray.d) * ray.d
                # (none for the environment: a plane wave from the path's own direction)
                scale = dr.select(
                    vertex.hit_emitter & ~environment & (not self.plane_waves),
                    -dr.rcp(record.chain_distance),
                    0.0,
                )
                source_mean = (scale * dr.dot(across, record.frame_x), scale * dr.dot(across, record.frame_y))
                return beta * self._film_factor(wavelengths, record, coating, resolved, source_mean)

            path.beta = dr.if_stmt(
                (path.beta,), resolve & coating.pending, film_factor, lambda beta: beta, label="film_factor"
            )
        record_first = resolve & record.first
        first_vertex.indirect = dr.select(
            record_first,
            self._coherence_sample(
                source_sigma,
                record.chain_distance,
                self._screen_angle_terms(*source_sigma, first_vertex.frame_x, first_vertex.frame_y),
                (~vertex.hit_emitter & ~overridden) | environment,
            ),
            first_vertex.indirect,
        )
        first_vertex.indirect_ready |= record_first

    def _film_factor(
        self,
        wavelengths: mi.Spectrum,
        record: PendingVertex,
        coating: PendingCoating,
        resolved: IncidentCoherence,
        source_mean: tuple[mi.Float, mi.Float],
    ) -> mi.Spectrum:
        """R(V)/R_incoherent of a pending film whose incident light is now ``resolved`` (Σ⊥ in the record's
        frame, r) from a source whose centre lies at ``source_mean`` (rad) from the path's direction: the
        path was sampled with the incoherent part at its own direction, so its throughput takes the
        relative interference modulation of the light the film passes towards the pixel
        (``bsdfs.thin_film.detected_light``; docs/physics_interactions.md §3, "What a pixel sees").

        The film's specular part, seen from the camera through mirrors and glass only, passes one direction
        of the source: the path's own (V = 1, the sampled terms). Its lobe passes its width around the
        mirror direction, and a film seen through a non-specular vertex the whole source
        (``~record.first``): there the phase is that of the detected mean direction, whose terms and shear
        are evaluated here (a symbolic branch; transmitted light keeps the path's phase)."""
        inverse_r2 = dr.rcp(dr.square(dr.maximum(resolved.distance_m, 1e-9)))
        source_cov = (
            resolved.sigma_xx * inverse_r2,
            resolved.sigma_xy * inverse_r2,
            resolved.sigma_yy * inverse_r2,
        )
        wavelength_count = len(wavelengths)

        def combined(*_: mi.Float) -> tuple[mi.Float, ...]:
            light = detected_light(
                tuple(coating.normal),
                source_mean,
                source_cov,
                tuple(coating.acceptance_mean),
                coating.lobe_variance,
                ~record.first,
                resolved.rect_source,
                wavelengths,
            )
            return (*light.means[0], *(c for covariance in light.covariances for c in covariance))

        def point(*_: mi.Float) -> tuple[mi.Float, ...]:
            return (*source_mean, *([mi.Float(0.0)] * (3 * wavelength_count)))

        # A point of a secondary source (Σ⊥ = 0) is what reaches the pixel whatever the film passes (C = 0,
        # the path's own point): a symbolic branch spares those lanes (most film records' in most scenes)
        # the combination.
        extended = (resolved.sigma_xx + resolved.sigma_yy) > 0.0
        state = dr.if_stmt(tuple(point()), extended, combined, point, label="detected_light")
        light = DetectedLight(
            [tuple(state[:2])] * wavelength_count,
            [tuple(state[2 + 3 * j : 5 + 3 * j]) for j in range(wavelength_count)],
        )
        # the hero's mean direction serves the four wavelengths (``bsdfs.thin_film.film_at_directions``)
        moved = (dr.square(light.means[0][0]) + dr.square(light.means[0][1]) > 1e-12) & ~coating.transmitted
        path_shear = (dr.dot(coating.separation, record.frame_x), dr.dot(coating.separation, record.frame_y))
        beams = len(coating.terms)
        params = self.kernels.params

        def at_mean(*_: mi.Float) -> tuple[mi.Float, ...]:
            spectra = VertexSpectra(params, coating.material, wavelengths, self.kernels.spectrum_offsets)
            thickness = coating.thickness if self._film_thickness_textured() else None
            terms, shears = film_at_directions(spectra, tuple(coating.normal), light.means, thickness)
            return (*terms, *(component for shear in shears for component in shear))

        def along_path(*_: mi.Float) -> tuple[mi.Float, ...]:
            return (*coating.terms, *(path_shear * len(wavelengths)))

        state = dr.if_stmt(tuple(along_path()), moved, at_mean, along_path, label="film_phase")
        terms = list(state[:beams])
        shears = [(state[beams + 2 * j], state[beams + 2 * j + 1]) for j in range(len(wavelengths))]
        reflectance = visible_reflectance(
            terms, shears, light.covariances, resolved, self.kernels.visibility, wavelengths
        )
        return reflectance / dr.maximum(terms[0], 1e-12)

    @dr.syntax
    def _start_or_carry(
        self,
        vertex: Vertex,
        sampled: MaterialSample,
        wo_world: mi.Vector3f,
        continue_path: mi.Bool,
        film_passthrough: mi.Bool,
        record: PendingVertex,
        coating: PendingCoating,
        first_vertex: FirstVertex,
    ) -> None:
        """Start a pending record at a non-specular vertex (its incident frame ⟂ the sampled direction; a
        thin film's separation and terms), or carry the pending one through a perfect mirror or refraction
        (r keeps growing, the frame and the film's separation are reflected with the beam)."""
        has_film = self.kernels.has(mat.INTERFERENCE_KINDS)
        # A new record at a non-specular vertex; carried through specular ones. Without thin films only
        # the first non-specular vertex needs its incident coherence.
        new_record = continue_path & vertex.nonspecular & ~film_passthrough & (~first_vertex.seen | has_film)
        incoming_fx = mi.Vector3f(record.frame_x)
        incoming_fy = mi.Vector3f(record.frame_y)
        if new_record:
            incoming_fx, incoming_fy = self._frame_for(-wo_world)
        record.frame_x = dr.select(new_record, incoming_fx, record.frame_x)
        record.frame_y = dr.select(new_record, incoming_fy, record.frame_y)
        new_first = new_record & ~first_vertex.seen
        first_vertex.frame_x = dr.select(new_first, incoming_fx, first_vertex.frame_x)
        first_vertex.frame_y = dr.select(new_first, incoming_fy, first_vertex.frame_y)
        first_vertex.direction = dr.select(new_first, wo_world, first_vertex.direction)
        record.first = dr.select(new_record, ~first_vertex.seen, record.first)
        record.pending |= new_record
        record.chain_distance = dr.select(new_record, 0.0, record.chain_distance)
        if has_film:
            # Both the film's Dirac part and its lobe interfere (Eq. 18): defer either.
            is_film = new_record & self.kernels.is_kind(vertex.kind, mat.INTERFERENCE_KINDS)
            coating.pending = dr.select(new_record, is_film, coating.pending)
            thickness = vertex.spectra.param(mat.FILM_THICKNESS_M)  # the local τ, from a texture
            # The shear between successive beams (docs/physics_interactions.md §3) for light arriving along
            # −wo: from the substrate (wo.z < 0; a transmitting film's frame is not flipped) the incident
            # index is the substrate's, else the exterior's (hero wavelength).
            incident_ior = dr.select(
                sampled.wo.z < 0.0,
                vertex.spectra[mat.ETA_ID][0],
                self.kernels.param(vertex.material, mat.EXTERIOR_IOR),
            )
            film_ior = vertex.spectra[mat.FILM_IOR_ID][0]
            shear = film_shear(vertex.frame.n, -wo_world, thickness, film_ior, incident_ior, OPS)
            coating.separation = dr.select(is_film, mi.Vector3f(*shear), coating.separation)
            coating.material = dr.select(is_film, vertex.material, coating.material)
            normal = vertex.frame.n
            coating.normal = dr.select(
                is_film,
                mi.Vector3f(
                    dr.dot(normal, incoming_fx), dr.dot(normal, incoming_fy), -dr.dot(normal, wo_world)
                ),
                coating.normal,
            )
            # The acceptance (``bsdfs.thin_film.detected_light``): the lobe's centre is the mirror image of
            # the direction the path arrived from; the specular part and transmission pass one direction.
            towards_camera = vertex.si.to_world(vertex.si.wi)
            mirror = 2.0 * dr.dot(towards_camera, normal) * normal - towards_camera
            lobe = ~sampled.delta & ~sampled.film.transmitted
            centre = dr.select(lobe, wo_world - mirror, 0.0)  # k_a − k, k = −wo
            coating.acceptance_mean = dr.select(
                is_film,
                mi.Point2f(dr.dot(centre, incoming_fx), dr.dot(centre, incoming_fy)),
                coating.acceptance_mean,
            )
            variance = self.kernels.lobe_variance(vertex.material, vertex.spectra.wavelengths)
            coating.lobe_variance = dr.select(is_film, dr.select(lobe, variance, 0.0), coating.lobe_variance)
            if self._film_thickness_textured():
                coating.thickness = dr.select(is_film, thickness, coating.thickness)
            coating.transmitted = dr.select(is_film, sampled.film.transmitted, coating.transmitted)
            coating.terms = dr.select(is_film, list(sampled.film.terms), list(coating.terms))
        # Through a perfect mirror / refraction the carried vectors follow the beam.
        through_specular = continue_path & (vertex.specular | film_passthrough) & record.pending
        record.frame_x = dr.select(
            through_specular, _reflect_vector(record.frame_x, vertex.frame.n), record.frame_x
        )
        record.frame_y = dr.select(
            through_specular, _reflect_vector(record.frame_y, vertex.frame.n), record.frame_y
        )
        coating.separation = dr.select(
            through_specular, _reflect_vector(coating.separation, vertex.frame.n), coating.separation
        )
        first_vertex.seen |= vertex.nonspecular

    def _advance_throughput(self, path: PathState, sampled: MaterialSample, continue_path: mi.Bool) -> None:
        """β and the hero-MIS ratios ρ after the sampled event, in the lanes ``continue_path``.

        Without a kind whose sampling depends on the hero (``sampled.pdf_ratios`` is None: every q_k = 1)
        the step p_eff/p_ref = mean_k ρ_k·1 is exactly 1 and ρ stays 1, so β·f/p_ref is all there is
        (the same floats; ρ then leaves the loop state)."""
        if sampled.pdf_ratios is None:
            path.beta = dr.select(continue_path, path.beta * sampled.weight, 0.0)
            return
        ratio_step = mean_over_wavelengths(path.hero_ratio * sampled.pdf_ratios)
        advance = continue_path & (ratio_step > 0.0)
        path.beta = dr.select(advance, path.beta * sampled.weight / dr.maximum(ratio_step, 1e-30), 0.0)
        path.hero_ratio = dr.select(
            advance, path.hero_ratio * sampled.pdf_ratios / dr.maximum(ratio_step, 1e-30), path.hero_ratio
        )

    @dr.syntax
    def _emitter_light(
        self,
        needed: mi.Bool,
        emitter_row: mi.UInt32,
        receiver: mi.Point3f,
        geometry: tuple[mi.Float, mi.Vector3f] | None,
    ) -> tuple[IncidentCoherence, CoherenceSample]:
        """The coherence of the light of emitter ``emitter_row`` at ``receiver``, a distance r from its centre
        along the direction d (centre → receiver): Σ⊥ of its whole silhouette in a frame ⟂ d, computed
        only in the lanes ``needed`` (zero elsewhere), and the diagnostics' record of it.

        ``geometry``: (r, d) where the caller reads them in every lane; ``None``: read here, in the lanes
        ``needed`` only (the emitter table's centre, a norm and a division less per bounce elsewhere; the
        other lanes' r is 0 there, and their diagnostics weight is 0)."""
        frame_x = mi.Vector3f(1.0, 0.0, 0.0)
        frame_y = mi.Vector3f(0.0, 1.0, 0.0)
        sigma = (mi.Float(0.0), mi.Float(0.0), mi.Float(0.0))
        angle_terms = (mi.Float(0.0), mi.Float(0.0))
        lazy = geometry is None
        distance_m, direction = mi.Float(0.0), mi.Vector3f(0.0, 0.0, 1.0)
        if not lazy:
            distance_m, direction = geometry
        if needed:
            if lazy:
                distance_m, direction = emitter_direction(
                    mi, self.context.emitter_flat, emitter_row, receiver
                )
            frame_x, frame_y = self._frame_for(direction)
            sigma = emitter_coherence(
                mi, self.context.emitter_flat, self.context.emitter_kinds, emitter_row, frame_x, frame_y
            )
            angle_terms = self._screen_angle_terms(*sigma, frame_x, frame_y)
        is_rect = emitter_is_rect(mi, self.context.emitter_flat, emitter_row)
        rect_modes = self._rect_modes(emitter_row, frame_x, frame_y)
        coherence = IncidentCoherence(*sigma, distance_m, frame_x, frame_y, is_rect, rect_modes)
        return coherence, self._coherence_sample(sigma, distance_m, angle_terms)

    # ------------------------------------------------------------------ Mitsuba interface
    def sample(
        self,
        scene: mi.Scene,
        sampler: mi.Sampler,
        ray: mi.RayDifferential3f,
        medium: mi.Medium = None,
        active: bool = True,
    ) -> tuple[mi.Spectrum, mi.Bool, list]:
        """Mitsuba's integrator interface (``mi.render`` with an hdrfilm), after ``attach``: radiance only;
        hgrender's own renderer (``worker.render.renderer``) also collects bands and diagnostics."""
        active = mi.Bool(active)
        result = self.trace(scene, sampler, mi.Ray3f(ray), active)
        return result.radiance, active, []

    def aov_names(self) -> list[str]:
        return []

    def to_string(self) -> str:
        return f"HGPathIntegrator[max_depth={self.max_depth}, rr_depth={self.rr_depth}]"

    # ------------------------------------------------------------------ the path loop
    @dr.syntax
    def trace(
        self,
        scene: mi.Scene,
        sampler: mi.Sampler,
        ray: mi.Ray3f,
        active: mi.Bool,
        wavelength_ratios: list[mi.Float] | None = None,
    ) -> PathResult:
        """One path per lane of ``ray``; ``wavelength_ratios``: (1/Λ)/p(λ_j) of the wavelengths' sampling
        density (``worker.render.wavelength_sampling``; None: uniform), for the luminance weights."""
        # (``self.context`` is read through ``self``: a dataclass local would become loop state.)
        kernels = self.kernels
        has_film = kernels.has(mat.INTERFERENCE_KINDS)
        has_nee_only = kernels.has(mat.NEE_ONLY_KINDS)
        coherence_materials = has_film or has_nee_only  # materials whose value depends on Σ⊥
        has_environment = self._has_environment()
        span_nm = self.context.bands.wavelength_max_nm - self.context.bands.wavelength_min_nm

        wavelengths = mi.Spectrum(ray.wavelengths)
        lane_weight = lane_weights(span_nm, len(wavelengths), wavelength_ratios)
        cie = self.context.cie1931
        y_weights = [
            cie1931_xyz(mi, cie, wavelengths[j])[1] * lane_weight[j] for j in range(len(wavelengths))
        ]
        # Loop state (Dr.Jit traverses each struct): the estimator, the pending coherence record and its
        # film, the first non-specular vertex, the diagnostics sums and the first-hit AOVs.
        path = PathState()
        record = PendingVertex()
        coating = PendingCoating(
            terms=[mi.Spectrum(0.0) for _ in range(kernels.max_beams if has_film else 0)]
        )
        first_vertex = FirstVertex()
        sums = DiagnosticSums()
        aov = FirstHit(material=mi.UInt32(self.context.black_material))

        while dr.hint(active, max_iterations=self.max_depth + 1, label="hg_path"):
            # ---------------------- Intersect and classify the vertex ----------------------
            si = scene.ray_intersect(ray, ray_flags=mi.RayFlags.All, coherent=path.depth == 0, active=active)
            valid = active & si.is_valid()
            segment = dr.select(valid, si.t, 0.0)
            record.chain_distance += segment

            material = dr.gather(
                mi.UInt32, self.context.shape_material, dr.reinterpret_array(mi.UInt32, si.shape), valid
            )
            kind = kernels.kind(material)
            # Before the bounce's symbolic branches, so that sampling, NEE and the pending record share
            # them (``VertexSpectra``).
            spectra = kernels.vertex_spectra(material, wavelengths, si)
            # A ray that leaves the scene reaches the environment, where there is one (Mitsuba's
            # ``si.emitter`` returns it for invalid interactions).
            reaches = active if has_environment else valid
            emitter_ptr = si.emitter(scene, reaches)
            hit_emitter = reaches & (emitter_ptr != None)  # noqa: E711 - Dr.Jit pointer comparison
            specular = valid & kernels.is_specular(material) & ~hit_emitter
            nonspecular = valid & ~specular & ~hit_emitter
            nee_only = kernels.is_kind(kind, mat.NEE_ONLY_KINDS)

            # ---------------------- First-hit AOVs (camera-visible surface) ----------------------
            first_hit = valid & (path.depth == 0)
            # Distance from the camera's centre (rays start on the near-clip plane, so si.t is shorter).
            aov.depth_m = dr.select(first_hit, dr.norm(si.p - self.context.camera_position), aov.depth_m)
            aov.normal = dr.select(first_hit, si.sh_frame.n, aov.normal)
            aov.material = dr.select(first_hit, material, aov.material)
            if kernels.textured:
                aov.uv = dr.select(first_hit, si.uv, aov.uv)

            # ---------------------- Shading frame (two-sided except transmitting interfaces) ------
            frame = mi.Frame3f(si.sh_frame)
            wi_world = -ray.d
            flip = (dr.dot(wi_world, frame.n) < 0) & kernels.two_sided(material)
            frame.n = dr.select(flip, -frame.n, frame.n)
            frame.t = dr.select(flip, -frame.t, frame.t)
            wi = frame.to_local(wi_world)
            continue_path = nonspecular | specular
            continue_path &= path.depth + 1 < self.max_depth
            vertex = Vertex(si, material, kind, spectra, frame, hit_emitter, specular, nonspecular)

            # ---------------------- Material sampling (random numbers: NEE, then material) -------
            nee_sample = sampler.next_2d(continue_path & nonspecular)
            bs = kernels.sample(
                material,
                wi,
                wavelengths,
                sampler.next_1d(continue_path),
                sampler.next_2d(continue_path),
                continue_path,
                spectra,
            )
            wo_world = frame.to_world(bs.wo)
            # A film on glass reflecting or refracting specularly keeps a pending record's coherence, like
            # smooth glass (the coated ball's far side passes on the light it transmits); its own
            # interference then uses the incoherent sum it was sampled with.
            film_passthrough = mi.Bool(False)
            if has_film:
                film_passthrough = nonspecular & record.pending & bs.delta
                film_passthrough &= kernels.param(material, mat.FILM_TRANSMITS) > 0.5

            # ---------------------- Resolve the pending record: its source is what we reached ----
            resolve = record.pending & (hit_emitter | (nonspecular & ~film_passthrough))
            emitter_row = self._emitter_lookup(emitter_ptr)
            # Symbolic branch: skipped by packets where no lane resolves (most bounces of most scenes).
            if resolve:
                self._resolve(
                    resolve,
                    vertex,
                    emitter_row,
                    segment,
                    ray,
                    wavelengths,
                    path,
                    record,
                    coating,
                    first_vertex,
                )
            record.pending &= ~resolve
            coating.pending &= ~resolve

            # ---------------------- Emission reached by material sampling (MIS with NEE) ---------
            ds = mi.DirectionSample3f(scene, si=si, ref=path.prev_si)
            em_pdf = scene.pdf_emitter_direction(path.prev_si, ds, ~path.prev_delta)
            hit_distance, _ = emitter_direction(mi, self.context.emitter_flat, emitter_row, path.prev_si.p)
            em_pdf = self._emitter_pdf(scene, em_pdf, emitter_row, hit_distance)
            mis = dr.select(path.prev_delta, 1.0, mis_weight(path.prev_pdf, em_pdf))
            mis = dr.select(path.prev_skip_emission, 0.0, mis)
            emitted = dr.select(hit_emitter, path.beta * mis * ds.emitter.eval(si, hit_emitter), 0.0)
            path.L += emitted

            # ---------------------- Emitter sampling (next-event estimation) ---------------------
            do_nee = continue_path & nonspecular
            ds_em, em_weight = scene.sample_emitter_direction(si, nee_sample, False, do_nee)
            do_nee &= ds_em.pdf != 0.0
            em_record_nee = self._emitter_lookup(ds_em.emitter)
            # The emitter's centre as seen from here: read in every lane by spheres' stable density and by
            # the coherence-sensitive terms (and, with plane waves, the diagnostics); else only where the
            # emitter's coherence is needed (``_emitter_light``).
            nee_geometry = None
            nee_r = None
            if self._has_sphere_emitters() or coherence_materials or self.plane_waves:
                nee_geometry = emitter_direction(mi, self.context.emitter_flat, em_record_nee, si.p)
                nee_r = nee_geometry[0]
            # Spheres: Mitsuba's weight L/pdf uses its float32 cone pdf (``_emitter_pdf``); with the stable
            # one it is L·Ω/selection. Visibility is tested here for all emitters, as Mitsuba would.
            em_pdf_nee = self._emitter_pdf(scene, ds_em.pdf, em_record_nee, nee_r)
            if self._has_sphere_emitters():
                sphere_nee, _ = sphere_solid_angle(mi, self.context.emitter_flat, em_record_nee, nee_r)
                em_radiance = ds_em.emitter.eval_direction(si, ds_em, do_nee & sphere_nee)
                em_weight = dr.select(sphere_nee, em_radiance / dr.maximum(em_pdf_nee, 1e-30), em_weight)
            do_nee &= ~scene.ray_test(si.spawn_ray_to(ds_em.p), do_nee)
            # The emitter's Σ⊥ matters for diagnostics at the first non-specular vertex and for
            # coherence-sensitive materials; elsewhere the symbolic branch is skipped.
            needs_nee_coherence = do_nee & (~first_vertex.seen | coherence_materials) & (not self.plane_waves)
            nee_coherence, direct_sample = self._emitter_light(
                needs_nee_coherence, em_record_nee, si.p, nee_geometry
            )
            # Beyond the first non-specular vertex every direction of the source reaches the pixel.
            nee_coherence.acceptance_unbounded = mi.Bool(first_vertex.seen)
            wo_em = frame.to_local(ds_em.d)
            # Coherence-sensitive terms use the direction to the emitter's centre (BRIEF): a grating's lobes
            # and a thin film's interference phase; the sampled point serves the radiometric terms only.
            wo_centre = wo_em
            environment_nee = self._is_environment(em_record_nee)  # no centre: the sampled direction
            if coherence_materials and not self.plane_waves:
                wo_centre = dr.select(environment_nee, wo_em, frame.to_local(-nee_geometry[1]))
            wo_eval = wo_em
            if has_nee_only:
                wo_eval = dr.select(nee_only, wo_centre, wo_em)
            bsdf_value, bsdf_pdf = kernels.eval_pdf(
                material, wi, wo_eval, wavelengths, nee_coherence, frame, do_nee, wo_centre, spectra
            )
            # Hero MIS: the material strategy's density is mean_k ρ_k p_k, the light's mean_k ρ_k p_L = p_L.
            material_pdf = mean_over_wavelengths(path.hero_ratio * bsdf_pdf)
            mis_em = dr.select(ds_em.delta | nee_only, 1.0, mis_weight(em_pdf_nee, material_pdf))
            direct = dr.select(do_nee, path.beta * bsdf_value * em_weight * mis_em, 0.0)
            path.L += direct
            # Diagnostics of this bounce's light: direct light at the first non-specular vertex carries
            # the emitter's own Σ⊥; emission reached by material sampling and later direct light, the
            # first vertex's resolved record. A lane has at most one of the two (an emitter's surface
            # does no NEE), so one sum of their luminance counts either: the same float sums as one
            # ``add`` each (the other adds zero), for a third of the arithmetic.
            direct_first = do_nee & ~first_vertex.seen
            counts = direct_first | (first_vertex.indirect_ready & first_vertex.seen)
            if has_environment:
                # Environment light by NEE at the first vertex is a VCZ sample with its own arrival
                # direction (the path's other one is the direction sampled from the first vertex).
                environment_first = direct_first & environment_nee
                counts &= ~environment_first
                environment_luminance = dr.select(environment_first, _luminance(y_weights, direct), 0.0)
                sums.vcz_direct_weight += environment_luminance
                sums.vcz_r += environment_luminance * FAR_DISTANCE_M
                sums.vcz_direct_direction = dr.select(environment_first, ds_em.d, sums.vcz_direct_direction)
            sums.add(
                dr.select(counts, _luminance(y_weights, emitted + direct), 0.0),
                dr.select(direct_first, direct_sample, first_vertex.indirect),
            )

            # ---------------------- Update the path; start or carry the pending record -----------
            # Path-level hero MIS: β_j = t_j/mean_k r_k (t_j = Π f_j/Π p_hero) advances by f_j/p_eff with
            # p_eff = mean_k ρ_k p_k(v) = p_ref·mean_k ρ_k q_k, and ρ_k by p_k/p_eff (normalised again).
            sampled_pdf = mean_over_wavelengths(
                path.hero_ratio * bs.pdf
            )  # before ρ is advanced: MIS of the next hit
            self._advance_throughput(path, bs, continue_path)
            path.eta = dr.select(continue_path, path.eta * bs.eta, path.eta)
            self._start_or_carry(
                vertex, bs, wo_world, continue_path, film_passthrough, record, coating, first_vertex
            )

            path.prev_si = mi.Interaction3f(si)
            path.prev_pdf = sampled_pdf
            path.prev_delta = bs.delta
            # Emission a NEE-only lobe reaches was counted by next-event estimation already.
            path.prev_skip_emission = dr.select(nonspecular, nee_only, False) & ~bs.delta
            ray = si.spawn_ray(wo_world)

            # ---------------------- Russian roulette (on β·η², prb.py) ---------------------------
            beta_max = dr.max(path.beta)
            rr_active = roulette_applies(path.depth, self.rr_depth)
            rr_probability = dr.minimum(beta_max * dr.square(path.eta), 0.95)
            survive = sampler.next_1d(continue_path) < rr_probability
            path.beta = dr.select(rr_active, path.beta * dr.rcp(dr.maximum(rr_probability, 1e-6)), path.beta)
            active = continue_path & (beta_max > 0.0) & (~rr_active | survive)
            path.depth += 1

        return PathResult(
            path.L,
            sums.weight,
            sums.moments.m_xx,
            sums.moments.m_xy,
            sums.moments.m_yy,
            sums.moments.r,
            sums.moments.cos2,
            sums.moments.sin2,
            sums.vcz_weight,
            sums.vcz_r,
            self._camera_coordinates(first_vertex.direction),
            sums.vcz_direct_weight,
            self._camera_coordinates(sums.vcz_direct_direction),
            aov.depth_m,
            aov.normal,
            kernels.textured_albedo(aov.material, wavelengths, aov.uv)
            if kernels.textured
            else kernels.albedo(aov.material, wavelengths),
        )


def register() -> None:
    """Register ``hg_path`` with Mitsuba (idempotent)."""
    mi.register_integrator("hg_path", lambda props: HGPathIntegrator(props))
