"""``hg_path``: a spectral path tracer that carries the coherence of light in Hermite-Gauss space.

Estimator. Unidirectional path tracing from the camera with next-event estimation and MIS (balance
heuristic, hero-wavelength pdfs, see ``bsdfs``), Russian roulette from ``rr_depth``, and Mitsuba's
``max_depth`` convention (1 = emitters seen directly, 2 = direct illumination). Emitter surfaces absorb.

Coherence state (paper §5.2: "each traced ray carries the shape matrix, transverse HG coefficients, the
propagation direction and distance r"). Because paths start at the camera, the coherence of the light a
vertex *receives* is known only once the path reaches that light's source. So each non-specular vertex
leaves a *pending* record, resolved at the next non-specular vertex or emitter hit:

* ``chain_distance_m`` r: the distance accumulated along perfect mirror/glass chains since the pending
  vertex (Θ is kept and r grows through Dirac interactions — §5 "Perfectly specular reflectors");
* ``frame_x``/``frame_y``: the transverse frame of the pending vertex's incident beam, reflected through
  the chain so that the source's Σ⊥ lands in that vertex's frame;
* ``film_separation``: for a thin-film vertex, the separation τ·n̂ (m) between the film's two interfaces,
  also carried through the chain, and its partially-coherent reflectance terms (linear in the visibilities).

At resolution the source is the emitter (whole emitter, BRIEF) or a non-specular surface: a *secondary*
incoherent source whose extent is the part of that surface that is lit and seen from the receiver (van
Cittert–Zernike, docs/physics.md §7). Its points are mutually incoherent, so each path, which reaches one
point of it, carries a point source (Σ⊥ = 0, phase along the sampled direction); averaging the paths
gives the partially coherent response of the whole lit patch. A material's explicit
``scattering_region_radius_m`` overrides this with a uniform disk of that radius in its tangent plane.

Diagnostics (BRIEF): M = (k/r)²Σ⊥ at λ = 550 nm of the light incident at the first non-specular vertex,
luminance-weighted over the pixel's paths: next-event contributions there use the emitter's Σ⊥, light
from emitters hit by BSDF sampling the emitter's Σ⊥, light from secondary sources the VCZ estimate of
``output.secondary_source_m``: the luminance-weighted covariance of the directions the pixel's paths
receive it from (per-sample sums ``vcz_*``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import drjit as dr

from hgcore.artifacts.layout import K_REFERENCE_PER_M, BandLayout
from hgcore.optics import sources
from hgcore.optics.coherence import degree_of_coherence
from hgcore.optics.frames import transverse_frame_components
from worker.mitsuba_setup import load_mitsuba
from worker.render import materials as mat
from worker.render.bsdfs import IncidentCoherence, MaterialKernels, combine_film_terms
from worker.render.drjit_ops import drjit_ops
from worker.render.emitters import emitter_coherence, emitter_direction, emitter_is_rect

# Python integrators subclass variant-specific classes: the variant must be chosen before this import
# (``load_mitsuba`` honours HGRENDER_VARIANT; ``auto`` picks cuda_ad_spectral when a GPU is usable).
mi = load_mitsuba()
OPS = drjit_ops()


@dataclass
class RenderContext:
    """Everything ``hg_path`` needs besides the Mitsuba scene (built by ``scene_compiler``)."""

    bands: BandLayout
    material_table: mat.MaterialTable
    material_flat: Any  # mi.Float
    spectra_flat: Any  # mi.Float
    shape_material: Any  # mi.UInt32: shape registry id -> material index
    emitter_flat: Any  # mi.Float
    emitter_index: Any  # mi.UInt32: emitter registry id -> emitter record
    emitter_kinds: set
    # (n, m) -> ĉ of the universal expansions (Eq. 14) used for visibilities: uniform disks (spheres, disks,
    # scattering regions) and uniform rectangles (rectangles, cylinders seen side-on).
    disk_coefficients: dict
    rect_coefficients: dict
    black_material: int  # index of the absorbing material (emitters, misses)
    rect_sources: bool  # whether any emitter is a rectangle or a cylinder
    camera_position: Any  # world-space centre of projection (Point3f)
    camera_right: Any  # world-space unit vectors of the image's +x and +y (up) directions
    camera_up: Any


@dataclass
class PathResult:
    radiance: Any  # mi.Spectrum at the sample's wavelengths
    diag_weight: Any
    diag_mxx: Any
    diag_mxy: Any
    diag_myy: Any
    diag_r: Any
    diag_cos2: Any
    diag_sin2: Any
    # Light from secondary sources (non-specular surfaces without a region override): its luminance, that
    # times r, and the direction (camera coordinates: right, up, forward) it arrives from at the first vertex.
    vcz_weight: Any
    vcz_r: Any
    vcz_direction: Any
    depth_m: Any
    normal: Any
    albedo: Any


def _luminance(y_weights: Any, value: Any) -> Any:
    """Y of a four-wavelength spectral estimate: Σ_j w_j·value_j with w_j = (Λ/4)·ȳ(λ_j) (CIE 1931 ȳ)."""
    total = mi.Float(0.0)
    for j in range(len(y_weights)):
        total += y_weights[j] * value[j]
    return total


def _reflect_vector(vector: Any, normal: Any) -> Any:
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
        self.kernels = MaterialKernels(
            mi,
            context.material_flat,
            context.spectra_flat,
            context.material_table,
            visibility=self.visibility,
        )

    # ------------------------------------------------------------------ coherence helpers
    def visibility(self, coherence: IncidentCoherence, separation_world: Any, wavelengths: Any) -> Any:
        """μ at the transverse part of ``separation_world`` (m) for each wavelength (Def. 4.1 / Eq. 18)."""
        xi = (dr.dot(separation_world, coherence.frame_x), dr.dot(separation_world, coherence.frame_y))
        sigma = (coherence.sigma_xx, coherence.sigma_xy, coherence.sigma_yy)
        result = mi.Spectrum(0.0)
        distance = dr.maximum(coherence.distance_m, 1e-9)
        context = self.context
        # With one mode both expansions are the same Gaussian: evaluate the rectangle's only when it differs.
        needs_rect = context.rect_coefficients != context.disk_coefficients and bool(context.rect_sources)
        for j in range(len(wavelengths)):
            wavelength_m = wavelengths[j] * 1e-9
            mu = degree_of_coherence(xi, sigma, distance, wavelength_m, context.disk_coefficients, OPS)
            if needs_rect:
                mu_rect = degree_of_coherence(
                    xi, sigma, distance, wavelength_m, context.rect_coefficients, OPS
                )
                mu = dr.select(coherence.rect_source, mu_rect, mu)
            result[j] = mu
        return result

    def _frame_for(self, direction: Any) -> tuple[Any, Any]:
        x_axis, y_axis = transverse_frame_components(
            (direction.x, direction.y, direction.z), tuple(self.context.camera_right), OPS
        )
        return mi.Vector3f(*x_axis), mi.Vector3f(*y_axis)

    def _scattering_region(self, material: Any, normal: Any, frame_x: Any, frame_y: Any):
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

    def _camera_coordinates(self, direction: Any) -> Any:
        """``direction`` in the camera's (right, up, forward) basis (orthonormal: covariances are kept)."""
        context = self.context
        forward = dr.cross(context.camera_right, context.camera_up)
        return mi.Vector3f(
            dr.dot(direction, context.camera_right),
            dr.dot(direction, context.camera_up),
            dr.dot(direction, forward),
        )

    def _emitter_lookup(self, emitter_ptr: Any) -> Any:
        registry_id = dr.reinterpret_array(mi.UInt32, emitter_ptr)
        return dr.gather(mi.UInt32, self.context.emitter_index, registry_id)

    def _screen_angle_terms(
        self, sxx: Any, sxy: Any, syy: Any, frame_x: Any, frame_y: Any
    ) -> tuple[Any, Any]:
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
    def trace(self, scene: mi.Scene, sampler: mi.Sampler, ray: mi.Ray3f, active: mi.Bool) -> PathResult:
        kinds = self.context.material_table.kinds
        has_film = mat.MaterialKind.THIN_FILM in kinds
        has_grating = mat.MaterialKind.GRATING in kinds
        span_nm = self.context.bands.wavelength_max_nm - self.context.bands.wavelength_min_nm
        film_beams = self.kernels.max_beams
        coherence_materials = has_film or has_grating

        wavelengths = mi.Spectrum(ray.wavelengths)
        y_weights = [
            mi.cie1931_y(wavelengths[j]) * (span_nm / len(wavelengths)) for j in range(len(wavelengths))
        ]
        L = mi.Spectrum(0.0)
        beta = mi.Spectrum(1.0)
        eta_scale = mi.Float(1.0)
        collapsed = mi.Bool(False)  # only the hero wavelength is left (dispersive refraction)
        depth = mi.UInt32(0)
        prev_si = dr.zeros(mi.SurfaceInteraction3f)
        prev_pdf = mi.Float(1.0)
        prev_delta = mi.Bool(True)
        prev_skip_emission = mi.Bool(False)
        # pending coherence resolution (see module docstring)
        pending = mi.Bool(False)
        pending_first = mi.Bool(False)
        chain_distance = mi.Float(0.0)
        frame_x = mi.Vector3f(0.0)
        frame_y = mi.Vector3f(0.0)
        first_frame_x = mi.Vector3f(0.0)
        first_frame_y = mi.Vector3f(0.0)
        film_pending = mi.Bool(False)
        film_transmitted = mi.Bool(False)
        film_separation = mi.Vector3f(0.0)
        film_material = mi.UInt32(0)
        film_position = mi.Point3f(0.0)
        film_normal = mi.Vector3f(0.0, 0.0, 1.0)
        chain_specular = mi.Bool(False)
        film_terms = [mi.Spectrum(0.0) for _ in range(film_beams if has_film else 0)]
        # diagnostics accumulators
        seen_nonspecular = mi.Bool(False)
        indirect_ready = mi.Bool(False)
        ind_mxx = mi.Float(0.0)
        ind_mxy = mi.Float(0.0)
        ind_myy = mi.Float(0.0)
        ind_r = mi.Float(0.0)
        ind_c2 = mi.Float(0.0)
        ind_s2 = mi.Float(0.0)
        d_w = mi.Float(0.0)
        d_mxx = mi.Float(0.0)
        d_mxy = mi.Float(0.0)
        d_myy = mi.Float(0.0)
        d_r = mi.Float(0.0)
        d_c2 = mi.Float(0.0)
        d_s2 = mi.Float(0.0)
        # light from secondary sources (VCZ estimate from the spread of its arrival directions)
        ind_vcz = mi.Bool(False)
        first_direction = mi.Vector3f(0.0, 0.0, 1.0)
        v_w = mi.Float(0.0)
        v_r = mi.Float(0.0)
        aov_depth = mi.Float(0.0)
        aov_normal = mi.Vector3f(0.0)
        aov_material = mi.UInt32(self.context.black_material)

        while dr.hint(active, max_iterations=self.max_depth + 1, label="hg_path"):
            si = scene.ray_intersect(ray, ray_flags=mi.RayFlags.All, coherent=depth == 0, active=active)
            valid = active & si.is_valid()
            segment = dr.select(valid, si.t, 0.0)
            chain_distance += segment

            material = dr.gather(
                mi.UInt32, self.context.shape_material, dr.reinterpret_array(mi.UInt32, si.shape), valid
            )
            kind = self.kernels.kind(material)
            emitter_ptr = si.emitter(scene, valid)
            hit_emitter = valid & (emitter_ptr != None)  # noqa: E711 - Dr.Jit pointer comparison
            specular = valid & self.kernels.is_specular(material) & ~hit_emitter
            nonspecular = valid & ~specular & ~hit_emitter

            # First-hit AOVs (camera-visible surface).
            first = valid & (depth == 0)
            # Distance from the camera's centre (rays start on the near-clip plane, so si.t is shorter).
            aov_depth = dr.select(first, dr.norm(si.p - self.context.camera_position), aov_depth)
            aov_normal = dr.select(first, si.sh_frame.n, aov_normal)
            aov_material = dr.select(first, material, aov_material)

            # --- shading frame (two-sided except for interfaces that transmit)
            frame = mi.Frame3f(si.sh_frame)
            wi_world = -ray.d
            flip = (dr.dot(wi_world, frame.n) < 0) & self.kernels.two_sided(material)
            frame.n = dr.select(flip, -frame.n, frame.n)
            frame.t = dr.select(flip, -frame.t, frame.t)
            wi = frame.to_local(wi_world)
            continue_path = nonspecular | specular
            continue_path &= depth + 1 < self.max_depth

            # --- sample the next direction (random numbers drawn in the order: NEE, then material)
            nee_sample = sampler.next_2d(continue_path & nonspecular)
            wo, weight, pdf, delta, sampled_film_terms, sampled_film_transmitted = self.kernels.sample(
                material,
                wi,
                wavelengths,
                sampler.next_1d(continue_path),
                sampler.next_2d(continue_path),
                continue_path,
                collapsed,
            )
            wo_world = frame.to_world(wo)
            # A Dirac refraction through a dispersive medium leaves the hero wavelength only (bsdfs).
            refracted = continue_path & delta & (wi.z * wo.z < 0)
            collapsed |= refracted & (self.kernels.param(material, mat.DISPERSIVE) > 0.5)
            # A film on glass reflecting or refracting specularly keeps a pending record's coherence, like
            # smooth glass (the coated ball's far side passes on the light it transmits); its own
            # interference then uses the incoherent sum it was sampled with.
            film_passthrough = mi.Bool(False)
            if has_film:
                film_passthrough = nonspecular & pending & delta
                film_passthrough &= self.kernels.param(material, mat.FILM_TRANSMITS) > 0.5

            # --- resolve the pending vertex's incident coherence: the source is what we just reached
            resolve = pending & (hit_emitter | (nonspecular & ~film_passthrough))
            em_record = self._emitter_lookup(emitter_ptr)
            # Symbolic branch: skipped by packets where no lane resolves (most bounces of most scenes).
            if resolve:
                em_sxx, em_sxy, em_syy = emitter_coherence(
                    mi,
                    self.context.emitter_flat,
                    self.context.emitter_kinds,
                    em_record,
                    frame_x,
                    frame_y,
                )
                (sr_xx, sr_xy, sr_yy), overridden = self._scattering_region(material, si.n, frame_x, frame_y)
                src_xx = dr.select(hit_emitter, em_sxx, sr_xx)
                src_xy = dr.select(hit_emitter, em_sxy, sr_xy)
                src_yy = dr.select(hit_emitter, em_syy, sr_yy)
                if self.plane_waves:
                    src_xx, src_xy, src_yy = mi.Float(0.0), mi.Float(0.0), mi.Float(0.0)
                # An emitter's coherence propagates from its centre (as in NEE): the last segment's length
                # becomes the distance from the segment's origin to that centre.
                centre_distance, _ = emitter_direction(mi, self.context.emitter_flat, em_record, ray.o)
                chain_distance = dr.select(
                    hit_emitter, chain_distance - segment + centre_distance, chain_distance
                )
                resolved = IncidentCoherence(
                    src_xx,
                    src_xy,
                    src_yy,
                    chain_distance,
                    frame_x,
                    frame_y,
                    hit_emitter & emitter_is_rect(mi, self.context.emitter_flat, em_record),
                )
                if has_film:
                    # An emitter reached straight from the film: its interference phase is taken towards the
                    # emitter's centre (BRIEF), as in next-event estimation; through mirrors, along the path.
                    centre_phase = hit_emitter & ~chain_specular & ~film_transmitted & (not self.plane_waves)
                    _, emitter_to_film = emitter_direction(
                        mi, self.context.emitter_flat, em_record, film_position
                    )
                    cos_centre = -dr.dot(emitter_to_film, film_normal)
                    centre_terms = self.kernels.film_terms(film_material, cos_centre, wavelengths)
                    phase_terms = list(film_terms)
                    for slot in range(film_beams):
                        phase_terms[slot] = dr.select(centre_phase, centre_terms[slot], film_terms[slot])
                    film_factor = combine_film_terms(
                        phase_terms,
                        lambda d, c=resolved, v=film_separation: self.visibility(c, v * d, wavelengths),
                    )
                    # The path was sampled with the incoherent part at its own direction: apply the relative
                    # interference modulation R(V)/R_incoherent of the phase direction.
                    film_factor = film_factor / dr.maximum(phase_terms[0], 1e-12)
                    beta = dr.select(resolve & film_pending, beta * film_factor, beta)
                record_indirect = resolve & pending_first
                scale2 = dr.square(K_REFERENCE_PER_M / dr.maximum(chain_distance, 1e-9))
                c2, s2 = self._screen_angle_terms(src_xx, src_xy, src_yy, first_frame_x, first_frame_y)
                ind_mxx = dr.select(record_indirect, scale2 * src_xx, ind_mxx)
                ind_mxy = dr.select(record_indirect, scale2 * src_xy, ind_mxy)
                ind_myy = dr.select(record_indirect, scale2 * src_yy, ind_myy)
                ind_r = dr.select(record_indirect, chain_distance, ind_r)
                ind_c2 = dr.select(record_indirect, c2, ind_c2)
                ind_s2 = dr.select(record_indirect, s2, ind_s2)
                ind_vcz = dr.select(record_indirect, ~hit_emitter & ~overridden, ind_vcz)
                indirect_ready |= record_indirect
            pending &= ~resolve
            film_pending &= ~resolve

            # --- emission reached by BSDF sampling (MIS with the previous vertex's NEE)
            ds = mi.DirectionSample3f(scene, si=si, ref=prev_si)
            em_pdf = scene.pdf_emitter_direction(prev_si, ds, ~prev_delta)
            mis = dr.select(prev_delta, 1.0, prev_pdf / dr.maximum(prev_pdf + em_pdf, 1e-20))
            mis = dr.select(prev_skip_emission, 0.0, mis)
            emitted = dr.select(hit_emitter, beta * mis * ds.emitter.eval(si, hit_emitter), 0.0)
            L += emitted
            weight_em = _luminance(y_weights, emitted)
            add_indirect = indirect_ready & seen_nonspecular
            v_w += dr.select(add_indirect & ind_vcz, weight_em, 0.0)
            v_r += dr.select(add_indirect & ind_vcz, weight_em * ind_r, 0.0)
            add_indirect &= ~ind_vcz
            d_w += dr.select(add_indirect, weight_em, 0.0)
            d_mxx += dr.select(add_indirect, weight_em * ind_mxx, 0.0)
            d_mxy += dr.select(add_indirect, weight_em * ind_mxy, 0.0)
            d_myy += dr.select(add_indirect, weight_em * ind_myy, 0.0)
            d_r += dr.select(add_indirect, weight_em * ind_r, 0.0)
            d_c2 += dr.select(add_indirect, weight_em * ind_c2, 0.0)
            d_s2 += dr.select(add_indirect, weight_em * ind_s2, 0.0)

            # --- next-event estimation at non-specular vertices
            do_nee = continue_path & nonspecular
            ds_em, em_weight = scene.sample_emitter_direction(si, nee_sample, True, do_nee)
            do_nee &= ds_em.pdf != 0.0
            em_record_nee = self._emitter_lookup(ds_em.emitter)
            nee_r, nee_dir = emitter_direction(mi, self.context.emitter_flat, em_record_nee, si.p)
            # The emitter's Σ⊥ matters for diagnostics at the first non-specular vertex and for
            # coherence-sensitive materials; elsewhere the symbolic branch is skipped.
            nee_fx = mi.Vector3f(1.0, 0.0, 0.0)
            nee_fy = mi.Vector3f(0.0, 1.0, 0.0)
            nee_sxx = mi.Float(0.0)
            nee_sxy = mi.Float(0.0)
            nee_syy = mi.Float(0.0)
            nee_c2 = mi.Float(0.0)
            nee_s2 = mi.Float(0.0)
            needs_nee_coherence = do_nee & (~seen_nonspecular | coherence_materials) & (not self.plane_waves)
            if needs_nee_coherence:
                nee_fx, nee_fy = self._frame_for(nee_dir)
                nee_sxx, nee_sxy, nee_syy = emitter_coherence(
                    mi,
                    self.context.emitter_flat,
                    self.context.emitter_kinds,
                    em_record_nee,
                    nee_fx,
                    nee_fy,
                )
                nee_c2, nee_s2 = self._screen_angle_terms(nee_sxx, nee_sxy, nee_syy, nee_fx, nee_fy)
            nee_coherence = IncidentCoherence(
                nee_sxx,
                nee_sxy,
                nee_syy,
                nee_r,
                nee_fx,
                nee_fy,
                emitter_is_rect(mi, self.context.emitter_flat, em_record_nee),
            )
            wo_em = frame.to_local(ds_em.d)
            # Coherence-sensitive terms use the direction to the emitter's centre (BRIEF): a grating's lobes
            # and a thin film's interference phase; the sampled point serves the radiometric terms only.
            wo_centre = wo_em if self.plane_waves else frame.to_local(-nee_dir)
            wo_eval = wo_em
            if has_grating:
                wo_eval = dr.select(kind == int(mat.MaterialKind.GRATING), wo_centre, wo_em)
            bsdf_value, bsdf_pdf = self.kernels.eval_pdf(
                material, wi, wo_eval, wavelengths, nee_coherence, frame.n, frame, do_nee, wo_phase=wo_centre
            )
            mis_em = dr.select(ds_em.delta, 1.0, ds_em.pdf / dr.maximum(ds_em.pdf + bsdf_pdf, 1e-20))
            if has_grating:
                mis_em = dr.select(kind == int(mat.MaterialKind.GRATING), 1.0, mis_em)
            direct = dr.select(do_nee, beta * bsdf_value * em_weight * mis_em, 0.0)
            L += direct
            weight_direct = _luminance(y_weights, direct)
            # Direct light at the first non-specular vertex: the emitter's own Σ⊥ (camera-aligned frame).
            at_first = do_nee & ~seen_nonspecular
            nee_scale2 = dr.square(K_REFERENCE_PER_M / dr.maximum(nee_r, 1e-9))
            direct_m = (nee_scale2 * nee_sxx, nee_scale2 * nee_sxy, nee_scale2 * nee_syy)
            use_ind = do_nee & seen_nonspecular & indirect_ready
            v_w += dr.select(use_ind & ind_vcz, weight_direct, 0.0)
            v_r += dr.select(use_ind & ind_vcz, weight_direct * ind_r, 0.0)
            use_ind &= ~ind_vcz
            w_first = dr.select(at_first, weight_direct, 0.0)
            w_later = dr.select(use_ind, weight_direct, 0.0)
            d_w += w_first + w_later
            d_mxx += w_first * direct_m[0] + w_later * ind_mxx
            d_mxy += w_first * direct_m[1] + w_later * ind_mxy
            d_myy += w_first * direct_m[2] + w_later * ind_myy
            d_r += w_first * nee_r + w_later * ind_r
            d_c2 += w_first * nee_c2 + w_later * ind_c2
            d_s2 += w_first * nee_s2 + w_later * ind_s2

            beta = dr.select(continue_path, beta * weight, 0.0)

            # Start a new pending record at a non-specular vertex; carry it through specular ones.
            # Without thin films only the first non-specular vertex needs its incident coherence.
            new_record = continue_path & nonspecular & ~film_passthrough & (~seen_nonspecular | has_film)
            incoming_fx = mi.Vector3f(frame_x)
            incoming_fy = mi.Vector3f(frame_y)
            if new_record:
                incoming_fx, incoming_fy = self._frame_for(-wo_world)
            frame_x = dr.select(new_record, incoming_fx, frame_x)
            frame_y = dr.select(new_record, incoming_fy, frame_y)
            first_frame_x = dr.select(new_record & ~seen_nonspecular, incoming_fx, first_frame_x)
            first_frame_y = dr.select(new_record & ~seen_nonspecular, incoming_fy, first_frame_y)
            first_direction = dr.select(new_record & ~seen_nonspecular, wo_world, first_direction)
            pending_first = dr.select(new_record, ~seen_nonspecular, pending_first)
            pending |= new_record
            chain_distance = dr.select(new_record, 0.0, chain_distance)
            if has_film:
                # Both the film's Dirac part and its lobe interfere (Eq. 18): defer either.
                is_film = new_record & (kind == int(mat.MaterialKind.THIN_FILM))
                film_pending = dr.select(new_record, is_film, film_pending)
                thickness = self.kernels.param(material, mat.FILM_THICKNESS_M)
                film_separation = dr.select(is_film, frame.n * thickness, film_separation)
                film_material = dr.select(is_film, material, film_material)
                film_position = dr.select(is_film, si.p, film_position)
                film_normal = dr.select(is_film, frame.n, film_normal)
                film_transmitted = dr.select(is_film, sampled_film_transmitted, film_transmitted)
                for index in range(film_beams):
                    film_terms[index] = dr.select(is_film, sampled_film_terms[index], film_terms[index])
            # Through a perfect mirror / refraction the carried vectors follow the beam.
            through_specular = continue_path & (specular | film_passthrough) & pending
            chain_specular = dr.select(new_record, False, chain_specular | through_specular)
            frame_x = dr.select(through_specular, _reflect_vector(frame_x, frame.n), frame_x)
            frame_y = dr.select(through_specular, _reflect_vector(frame_y, frame.n), frame_y)
            film_separation = dr.select(
                through_specular, _reflect_vector(film_separation, frame.n), film_separation
            )
            seen_nonspecular |= nonspecular

            prev_si = si
            prev_pdf = pdf
            prev_delta = delta
            prev_skip_emission = dr.select(nonspecular, kind == int(mat.MaterialKind.GRATING), False) & ~delta
            ray = si.spawn_ray(wo_world)

            # Russian roulette
            beta_max = dr.max(beta)
            rr_active = depth >= self.rr_depth
            rr_probability = dr.minimum(beta_max * dr.square(eta_scale), 0.95)
            survive = sampler.next_1d(continue_path) < rr_probability
            beta = dr.select(rr_active, beta * dr.rcp(dr.maximum(rr_probability, 1e-6)), beta)
            active = continue_path & (beta_max > 0.0) & (~rr_active | survive)
            depth += 1

        aov_albedo = self.kernels.albedo(aov_material, wavelengths)
        return PathResult(
            L,
            d_w,
            d_mxx,
            d_mxy,
            d_myy,
            d_r,
            d_c2,
            d_s2,
            v_w,
            v_r,
            self._camera_coordinates(first_direction),
            aov_depth,
            aov_normal,
            aov_albedo,
        )


def register() -> None:
    """Register ``hg_path`` with Mitsuba (idempotent)."""
    mi.register_integrator("hg_path", lambda props: HGPathIntegrator(props))
