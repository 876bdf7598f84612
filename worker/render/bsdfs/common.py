"""The interface every material kind implements (``Material``), and what the kinds share.

Conventions (all kinds). Directions are in the local shading frame (z = normal, flipped towards the
incident side for two-sided materials); ``wi`` points to the previous vertex (towards the camera), ``wo`` to
the next one (towards the light); by reciprocity the formulas of ``hgcore.optics`` are evaluated with the
light arriving along ``wo``. ``eval_pdf`` returns f·|cos θo| per wavelength and the MIS densities in
solid angle *per wavelength*: p_k, the density with which the lobe would be sampled were λ_k the hero.
``sample`` returns a ``MaterialSample``: the weight f_j·|cos θo|/p_ref per wavelength for a reference density
p_ref the kind chooses (the four-wavelength mean where the lobe depends on λ, the hero's for a discrete choice
made with the hero's probabilities), ``pdf_ratios`` q_k = p_k/p_ref with p_k the probability density of the
sampled outcome had λ_k been the hero (discrete choices included; 0 where hero k could not have produced it,
e.g. a dispersive refraction), the per-wavelength MIS pdfs (1 for a Dirac part), whether the part sampled is a
Dirac delta, and the relative index η = n_transmitted/n_incident of the sampled event (1 for reflection),
which Russian roulette divides out. The integrator combines the q_k along the path into the path-level
hero-wavelength MIS of Wilkie et al. 2014 ("Hero wavelength spectral sampling", §4; docs/integrator.md).

Coherence enters only through ``IncidentCoherence`` (Σ⊥, r and frame of the light a vertex receives) and
``VisibilityModel`` (μ at a separation, Eq. 18), and only for thin films and gratings (Thm 5.1(i)).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple

import drjit as dr
import mitsuba as mi

from hgcore.optics.coherence import degree_of_coherence
from hgcore.optics.complex_pair import ComplexPair
from hgcore.optics.fresnel import fresnel_reflectance
from hgcore.optics.rough_surface import RoughSurface
from worker.render import materials as mat
from worker.render.drjit_ops import drjit_ops
from worker.render.spectral import lookup
from worker.render.textures import TextureKernels

OPS = drjit_ops()


@dataclass
class IncidentCoherence:
    """Coherence of the light arriving at a vertex: Σ⊥ (m², in frame_x/frame_y ⟂ propagation), r (m)."""

    sigma_xx: mi.Float
    sigma_xy: mi.Float
    sigma_yy: mi.Float
    distance_m: mi.Float
    frame_x: mi.Vector3f  # world-space unit vectors spanning the transverse plane
    frame_y: mi.Vector3f
    rect_source: mi.Bool | bool = False  # True where the source expands like a uniform rectangle (Eq. 14)
    # Per-lane ĉ_nm where rect_source (cylinders: by their view, ``emitters.CylinderModes``); None: the
    # universal rectangle's.
    rect_modes: dict[tuple[int, int], mi.Float] | None = None
    # The vertex is seen through a non-specular vertex (the path passed one since the camera): every
    # direction of the source reaches the pixel, whatever the vertex's own acceptance (``hgcore.optics.
    # acceptance``: K = I, the paper's Eq. 18).
    acceptance_unbounded: mi.Bool | bool = False


@dataclass(frozen=True)
class VisibilityModel:
    """μ(ξ) of the light a vertex receives (Def. 4.1 / Eq. 18), from the universal expansions of Eq. 14.

    ``disk_coefficients`` / ``rect_coefficients``: (n, m) → ĉ of uniform disks (spheres, disks, scattering
    regions) and uniform rectangles (rectangles; cylinders use ``IncidentCoherence.rect_modes``, their own
    view-dependent modes, where the scene has them); ``rect_sources``: whether any emitter of the scene
    expands like a rectangle (else the rectangle's branch is not compiled).
    """

    disk_coefficients: dict[tuple[int, int], float]
    rect_coefficients: dict[tuple[int, int], float]
    rect_sources: bool

    def at(
        self, coherence: IncidentCoherence, separation_world: mi.Vector3f, wavelengths: mi.Spectrum
    ) -> mi.Spectrum:
        """μ at the transverse part of ``separation_world`` (m) for each wavelength."""
        xi = (dr.dot(separation_world, coherence.frame_x), dr.dot(separation_world, coherence.frame_y))
        sigma = (coherence.sigma_xx, coherence.sigma_xy, coherence.sigma_yy)
        result = mi.Spectrum(0.0)
        distance = dr.maximum(coherence.distance_m, 1e-9)
        for j in range(len(wavelengths)):
            result[j] = self.degree(coherence, xi, sigma, distance, wavelengths[j] * 1e-9)
        return result

    def lobe_modes(self, coherence: IncidentCoherence) -> LobeModes:
        """The modes of the light ``coherence`` describes, for lobes shaped by them (gratings): with one mode
        every source is the Gaussian (``None``, the cheaper closed form)."""
        if len(self.disk_coefficients) == 1:
            return LobeModes(None, None, False)
        return LobeModes(self.disk_coefficients, self._rect_modes(coherence), coherence.rect_source)

    def _rect_modes(self, coherence: IncidentCoherence) -> dict[tuple[int, int], Any] | None:
        """The rectangle's coefficients for the light ``coherence`` describes (a cylinder's own, per lane,
        where it has them), or None where they equal the disk's (one mode) or no source is a rectangle."""
        if self.rect_coefficients == self.disk_coefficients or not self.rect_sources:
            return None
        return self.rect_coefficients if coherence.rect_modes is None else coherence.rect_modes

    def degree(
        self,
        coherence: IncidentCoherence,
        xi: tuple[mi.Float, mi.Float],
        sigma: tuple[mi.Float, mi.Float, mi.Float],
        distance_m: mi.Float | float,
        wavelength_m: mi.Float,
    ) -> mi.Float:
        """μ(ξ) at one wavelength for the transverse covariance ``sigma`` (m²) after ``distance_m``, with the
        modes of the source ``coherence`` describes (its disk or rectangle expansion). With Σ = r²C and
        r = 1 this is the angular form: C in rad² (``hgcore.optics.acceptance``)."""
        mu = degree_of_coherence(xi, sigma, distance_m, wavelength_m, self.disk_coefficients, OPS)
        # With one mode both expansions are the same Gaussian: evaluate the rectangle's only when it differs.
        rect_coefficients = self._rect_modes(coherence)
        if rect_coefficients is not None:
            mu_rect = degree_of_coherence(xi, sigma, distance_m, wavelength_m, rect_coefficients, OPS)
            mu = dr.select(coherence.rect_source, mu_rect, mu)
        return mu


class LobeModes(NamedTuple):
    """The coefficient sets a lobe shaped by the source's modes uses (``VisibilityModel.lobe_modes``): the
    disk's (None: one mode, the Gaussian), the rectangle's where it differs (None: the same) and the lanes
    whose source expands like a rectangle."""

    disk: dict[tuple[int, int], float] | None
    rect: dict[tuple[int, int], mi.Float] | dict[tuple[int, int], float] | None
    rect_source: mi.Bool | bool


class FilmSample(NamedTuple):
    """A thin film's partially-coherent terms at the sampled direction (``thin_film.film_terms``): the
    reflectance terms [R_incoherent, X_1 …], or the transmittance terms where ``transmitted``."""

    terms: list[mi.Spectrum]
    transmitted: mi.Bool


class MaterialSample(NamedTuple):
    """One sampled scattering event (module docstring); ``film`` only from thin films; ``pdf_ratios``
    q_k = p_k/p_ref (``None``: 1 for every wavelength, a sampler that does not depend on the hero)."""

    wo: mi.Vector3f
    weight: mi.Spectrum
    pdf: mi.Spectrum
    delta: mi.Bool
    eta: mi.Float
    film: FilmSample | None = None
    pdf_ratios: mi.Spectrum | None = None


class MaterialParams:
    """What a kind's kernels read: the fixed-stride material table (``materials``), the spectra it names
    and the scene's ``VisibilityModel``."""

    def __init__(
        self,
        table: mi.Float,
        spectra: mi.Float,
        materials: mat.MaterialTable,
        visibility: VisibilityModel,
        textures: TextureKernels | None = None,
    ) -> None:
        self.table = table
        self.spectra = spectra
        self.materials = materials
        #: μ of the incident light, for the kinds that interfere (thin films)
        self.visibility = visibility
        #: the scene's texture lookups, and the parameters some material reads from a texture
        self.textures = textures
        self.textured = materials.textured_parameters() if textures is not None else frozenset()
        #: some conductor has a tint (``materials.TINT_ID``): only then is a tint looked up
        self.tinted = materials.tinted()
        #: beams of the partially coherent film sums (the largest of the scene's films, at least two)
        self.max_beams = max(materials.max_beams(), 2)
        #: some film absorbs: the film index is complex, n_f + iκ_f (``materials.FILM_EXTINCTION``)
        self.film_absorbing = materials.film_absorbing()

    def param(self, material: mi.UInt32, offset: int) -> mi.Float:
        return dr.gather(mi.Float, self.table, material * mat.STRIDE + offset)

    def spectrum(
        self, material: mi.UInt32, offset: int, wavelengths: mi.Spectrum, active: mi.Bool | bool = True
    ) -> mi.Spectrum:
        spectrum_id = mi.UInt32(self.param(material, offset))
        return lookup(mi, self.spectra, spectrum_id, wavelengths, active)

    def kind(self, material: mi.UInt32) -> mi.UInt32:
        return mi.UInt32(self.param(material, mat.KIND))

    def tint(self, reflectance: mi.Spectrum, spectra: VertexSpectra) -> mi.Spectrum:
        """A conductor's reflectance times its tint (``materials.TINT_ID``), where a scene has tints."""
        return reflectance * spectra[mat.TINT_ID] if self.tinted else reflectance

    def interface_reflectance(self, spectra: VertexSpectra, cos_theta: mi.Float | float) -> mi.Spectrum:
        """Unpolarised Fresnel reflectance F(θ) of the (conductor or substrate) interface of the material
        whose spectra are ``spectra``."""
        exterior = self.param(spectra.material, mat.EXTERIOR_IOR)
        eta = spectra[mat.ETA_ID] / exterior
        kappa = spectra[mat.KAPPA_ID] / exterior
        result = mi.Spectrum(0.0)
        for j in range(len(spectra.wavelengths)):
            result[j] = fresnel_reflectance(cos_theta, ComplexPair(eta[j], kappa[j]), OPS)
        return result

    def hero_collapse(
        self, weight: mi.Spectrum, ratios: mi.Spectrum, material: mi.UInt32, refracted: mi.Bool
    ) -> tuple[mi.Spectrum, mi.Spectrum]:
        """A refraction through a dispersive medium bends each wavelength differently: only the hero's
        direction was sampled, so the other wavelengths' f is 0 there (weights zeroed) and so is the density
        with which another hero would have produced it (q_k = 0 for k ≠ hero). The path-level MIS then
        gives the hero its factor 4 (β_hero = t_hero/mean_k r_k with r = (1, 0, 0, 0)), once: a second
        collapse finds r_k = 0 already."""
        collapse = refracted & (self.param(material, mat.DISPERSIVE) > 0.5)
        result, q = mi.Spectrum(weight), mi.Spectrum(ratios)
        for j in range(1, len(result)):
            result[j] = dr.select(collapse, 0.0, weight[j])
            q[j] = dr.select(collapse, 0.0, ratios[j])
        return result, q


class VertexSpectra:
    """A material's spectra (``materials`` offsets ``*_ID``) at a path's wavelengths, ``spectra[offset]``.

    Why: a bounce reads the same spectra for material sampling, next-event estimation and the pending
    record, but Dr.Jit merges identical lookups only within one symbolic scope, and the bounce's symbolic
    branches (resolving a record, the emitter's coherence) lie between those reads. So the integrator looks
    the vertex's spectra up once, before the branches (``offsets``: those of the scene's material kinds,
    ``MaterialKernels.spectrum_offsets``), and every read shares them. A spectrum not looked up then is
    looked up at each read and never kept: a value made inside a symbolic branch must not leave it.
    """

    def __init__(
        self,
        params: MaterialParams,
        material: mi.UInt32,
        wavelengths: mi.Spectrum,
        offsets: Iterable[int] = (),
        uv: mi.Point2f | None = None,
        active: mi.Bool | bool = True,
    ) -> None:
        self.params = params
        self.material = material
        self.wavelengths = wavelengths
        # Textured parameters at the vertex's texture coordinates ``uv`` (lanes ``active``): (the lanes
        # whose material has the texture, its value there). Without ``uv`` no texture is read.
        self._textured: dict[int, tuple[mi.Bool, mi.Float | mi.Spectrum]] = {}
        if uv is not None:
            for offset in sorted(params.textured):
                self._textured[offset] = self._texture(offset, uv, active)
        self._looked_up = {offset: self._spectrum(offset) for offset in offsets}

    def _texture(
        self, offset: int, uv: mi.Point2f, active: mi.Bool | bool
    ) -> tuple[mi.Bool, mi.Float | mi.Spectrum]:
        """(the lanes whose material has a texture for parameter ``offset``, its value there at ``uv``)."""
        params, wavelengths = self.params, self.wavelengths
        binding = params.param(self.material, mat.TEXTURE_BINDINGS[offset])
        has_texture = active & (binding > 0.5)
        index = mi.UInt32(dr.maximum(binding - 1.0, 0.0))
        colour = offset in mat.COLOUR_PARAMETERS

        def look_up(_: mi.Float | mi.Spectrum) -> tuple[mi.Float | mi.Spectrum]:
            if colour:
                return (params.textures.reflectance(index, uv, wavelengths, has_texture),)
            return (params.textures.scalar(index, uv, has_texture),)

        # A symbolic branch: packets without a lane of a textured material skip the lookup.
        (value,) = dr.if_stmt(
            (mi.Spectrum(0.0) if colour else mi.Float(0.0),),
            has_texture,
            look_up,
            lambda kept: (kept,),
            label=f"texture_{offset}",
        )
        return has_texture, value

    def _spectrum(self, offset: int) -> mi.Spectrum:
        textured = self._textured.get(offset)
        if textured is None:
            return self.params.spectrum(self.material, offset, self.wavelengths)
        # the table's spectrum only where the material has no texture (its gathers skip the other lanes)
        value = self.params.spectrum(self.material, offset, self.wavelengths, ~textured[0])
        return dr.select(textured[0], textured[1], value)

    def __getitem__(self, offset: int) -> mi.Spectrum:
        value = self._looked_up.get(offset)
        if value is None:
            return self._spectrum(offset)
        return value

    def param(self, offset: int) -> mi.Float:
        """A scalar parameter of the vertex's material: its texture's value where it has one (SI units),
        else the table's."""
        value = self.params.param(self.material, offset)
        textured = self._textured.get(offset)
        return value if textured is None else dr.select(textured[0], textured[1], value)


class ShadingPoint(NamedTuple):
    """A vertex as a material sees it (the part of Mitsuba's SurfaceInteraction a BSDF reads): the
    material index, ``wi`` (local frame, towards the previous vertex), the path's wavelengths (nm), the
    material's spectra at them, the world-space shading frame (gratings' axes, a film's normal; sampling
    does not need it)."""

    material: mi.UInt32
    wi: mi.Vector3f
    wavelengths: mi.Spectrum
    spectra: VertexSpectra
    frame: mi.Frame3f | None = None


class Material:
    """The kernels of one material kind (one module per kind in this package).

    A *table* kind (``per_material = False``: diffuse, mirror, smooth dielectric) reads everything from the
    material table and compiles one branch for all its materials; a *model* kind (rough conductor, rough
    dielectric, thin film, grating) compiles one branch per material with the constants of its optics
    model (``model``, the record's ``MaterialRow.model``) built in. ``MaterialKernels`` (``dispatch``)
    selects the branch of each lane with ``selects``.
    """

    kind: ClassVar[mat.MaterialKind]
    per_material: ClassVar[bool] = False
    #: the spectra (``materials`` offsets) the kind's sampling and evaluation read (``VertexSpectra``)
    spectra: ClassVar[tuple[int, ...]] = ()
    #: whether ``sample`` returns ``pdf_ratios`` (its probabilities depend on the hero wavelength)
    hero_ratios: ClassVar[bool] = True

    def __init__(self, params: MaterialParams, index: int | None = None) -> None:
        self.params = params
        self.index = index  # the material's table index (model kinds only)
        self.model = None if index is None else params.materials.records[index].model

    def kernel_tables(self) -> list[mi.Float]:
        """Arrays of the kind's own that its kernels read besides ``params``' (what a frozen render pass
        names as inputs; ``renderer``)."""
        return []

    @property
    def record(self) -> mat.MaterialRow:
        assert self.index is not None, "table kinds have no single record"
        return self.params.materials.records[self.index]

    @property
    def label(self) -> str:
        """The branch's name in Dr.Jit's IR (symbolic branches)."""
        suffix = "" if self.index is None else f"[{self.index}]"
        return f"{self.kind.name.lower()}{suffix}"

    def surface(self, point: ShadingPoint) -> RoughSurface:
        """The material's rough surface (``model``) at ``point``: σ_h and ℓ_c from its textures where it
        has them (per lane, ``RoughSurface.local``), else the model's constants (compiled in)."""
        record, model = self.record, self.model
        rms_textured = record.textured(mat.ROUGHNESS_RMS_M)
        length_textured = record.textured(mat.CORRELATION_LENGTH_M)
        if not (rms_textured or length_textured):
            return model
        return model.local(
            point.spectra.param(mat.ROUGHNESS_RMS_M) if rms_textured else model.rms_height_m,
            point.spectra.param(mat.CORRELATION_LENGTH_M) if length_textured else model.correlation_length_m,
        )

    def selects(self, material: mi.UInt32, kind: mi.UInt32) -> mi.Bool:
        """Lanes whose material this branch handles."""
        if self.per_material:
            return material == self.index
        return kind == int(self.kind)

    def sample_domain(self, wi: mi.Vector3f, active: mi.Bool) -> mi.Bool:
        """Lanes this kind samples: reflectors only from their front side."""
        return active & (wi.z > 0)

    def eval_domain(self, wi: mi.Vector3f, wo: mi.Vector3f, active: mi.Bool) -> mi.Bool:
        """Lanes where ``eval_pdf`` applies: reflectors with both directions in front."""
        return active & (wi.z > 0) & (wo.z > 0)

    def sample(self, point: ShadingPoint, sample1: mi.Float, sample2: mi.Point2f) -> MaterialSample:
        """Sample the next direction from ``point`` with the uniforms ``sample1``, ``sample2``."""
        raise NotImplementedError

    def eval_pdf(
        self, point: ShadingPoint, wo: mi.Vector3f, coherence: IncidentCoherence, wo_phase: mi.Vector3f
    ) -> tuple[mi.Spectrum, mi.Spectrum] | None:
        """(f·|cos θo|, per-wavelength MIS pdfs p_k) of the non-Dirac part for light arriving along ``wo``
        with the coherence ``coherence``; ``None`` for a purely Dirac kind. ``wo_phase``: the direction whose
        interference phase a thin film uses (module ``thin_film``)."""
        return None


def refract(wi: mi.Vector3f, eta_ti: mi.Float, cos_t: mi.Float) -> mi.Vector3f:
    """Snell refraction of ``wi`` (local frame) with relative index η_ti = n_t/n_i and |cos θ_t|."""
    return mi.Vector3f(-wi.x / eta_ti, -wi.y / eta_ti, -dr.mulsign(cos_t, wi.z))


def vec(v: mi.Vector3f) -> tuple[mi.Float, mi.Float, mi.Float]:
    """A vector as the component tuple the ``hgcore.optics`` formulas take."""
    return (v.x, v.y, v.z)
