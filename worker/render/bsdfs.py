"""Kernel-side evaluation and sampling of hgrender materials, for the ``hg_path`` integrator.

All functions run inside the integrator's symbolic loop on Dr.Jit arrays. Directions are in the local
shading frame (z = normal, flipped towards the incident side for two-sided materials); ``wi`` points to the
previous vertex (towards the camera), ``wo`` to the next one (towards the light); by reciprocity the
formulas of ``hgcore.optics`` are evaluated with the light arriving along ``wo``. ``eval_pdf`` returns
f·cos θo and the hero-wavelength MIS density in solid angle — the mean over the four wavelengths of the
per-wavelength sampling density, so that wavelength-dependent lobes (gratings, PSD lobes) combine without
bias (Wilkie et al. 2014, "Hero wavelength spectral sampling").

The physics lives in ``hgcore.optics`` (rough surfaces: Eq. 15; thin films: Eq. 18; gratings: Eq. 20);
this module gathers parameters and dispatches. Diffuse, mirror and smooth dielectric materials read their
spectra from the material table (one kernel branch per kind); rough, thin-film and grating materials get
one branch per material with their constants compiled in (their optics models are Python objects).
Coherence enters only through ``IncidentCoherence`` and only for thin films and gratings (Thm 5.1(i)).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import drjit as dr

from hgcore.optics import grating as grating_model
from hgcore.optics import rough_surface
from hgcore.optics.complex_pair import ComplexPair
from hgcore.optics.fresnel import fresnel_dielectric, fresnel_reflectance
from hgcore.optics.thin_film import (
    combine_reflectance_terms,
    film_amplitudes,
    reflectance_terms,
    transmission_terms,
)
from worker.render import materials as mat
from worker.render.drjit_ops import drjit_ops
from worker.render.spectral import lookup

OPS = drjit_ops()


@dataclass
class IncidentCoherence:
    """Coherence of the light arriving at a vertex: Σ⊥ (m², in frame_x/frame_y ⟂ propagation), r (m)."""

    sigma_xx: Any
    sigma_xy: Any
    sigma_yy: Any
    distance_m: Any
    frame_x: Any  # world-space unit vectors spanning the transverse plane
    frame_y: Any
    rect_source: Any = False  # True where the source expands like a uniform rectangle (Eq. 14)


def _vec(v: Any) -> tuple[Any, Any, Any]:
    return (v.x, v.y, v.z)


class MaterialKernels:
    """Gathers material parameters and dispatches to the formulas of the kinds present in the scene."""

    def __init__(
        self,
        mi: Any,
        table: Any,
        spectra: Any,
        materials: mat.MaterialTable,
        visibility: Callable[[IncidentCoherence, Any, Any], Any],
    ) -> None:
        self.mi = mi
        self.table = table
        self.spectra = spectra
        self.materials = materials
        self.kinds = materials.kinds
        self.max_beams = max(materials.max_beams(), 2)
        self.visibility = visibility  # (coherence, separation_world_m, wavelengths) -> Spectrum μ
        self._fraction_tables: dict[int, tuple[rough_surface.RoughSurface, Any]] = {}

    # ---------------------------------------------------------------- parameters
    def param(self, material: Any, offset: int) -> Any:
        return dr.gather(self.mi.Float, self.table, material * mat.STRIDE + offset)

    def spectrum(self, material: Any, offset: int, wavelengths: Any) -> Any:
        spectrum_id = self.mi.UInt32(self.param(material, offset))
        return lookup(self.mi, self.spectra, spectrum_id, wavelengths)

    def kind(self, material: Any) -> Any:
        return self.mi.UInt32(self.param(material, mat.KIND))

    def two_sided(self, material: Any) -> Any:
        """Whether the shading frame is flipped towards the incident side: not for interfaces that
        transmit (dielectrics, rough dielectrics, films on a dielectric), whose sides differ."""
        kind = self.kind(material)
        transmits = (kind == int(mat.MaterialKind.DIELECTRIC)) | (
            kind == int(mat.MaterialKind.ROUGH_DIELECTRIC)
        )
        if mat.MaterialKind.THIN_FILM in self.kinds:
            film = kind == int(mat.MaterialKind.THIN_FILM)
            transmits |= film & (self.param(material, mat.FILM_TRANSMITS) > 0.5)
        return ~transmits

    def is_specular(self, material: Any) -> Any:
        kind = self.kind(material)
        return (kind == int(mat.MaterialKind.MIRROR)) | (kind == int(mat.MaterialKind.DIELECTRIC))

    def interface_reflectance(self, material: Any, cos_theta: Any, wavelengths: Any) -> Any:
        """Unpolarised Fresnel reflectance F(θ) of the material's (conductor or substrate) interface."""
        exterior = self.param(material, mat.EXTERIOR_IOR)
        eta = self.spectrum(material, mat.ETA_ID, wavelengths) / exterior
        kappa = self.spectrum(material, mat.KAPPA_ID, wavelengths) / exterior
        result = self.mi.Spectrum(0.0)
        for j in range(len(wavelengths)):
            result[j] = fresnel_reflectance(cos_theta, ComplexPair(eta[j], kappa[j]), OPS)
        return result

    def albedo(self, material: Any, wavelengths: Any) -> Any:
        """Directional-hemispherical reflectance at normal incidence, for the albedo AOV."""
        kind = self.kind(material)
        diffuse = kind == int(mat.MaterialKind.DIFFUSE)
        reflective = (kind != int(mat.MaterialKind.DIFFUSE)) & (kind != int(mat.MaterialKind.BLACK))
        value = dr.select(diffuse, self.spectrum(material, mat.REFLECTANCE_ID, wavelengths), 0.0)
        return dr.select(reflective, self.interface_reflectance(material, 1.0, wavelengths), value)

    def _per_material(self, kind: mat.MaterialKind) -> list[tuple[int, Any]]:
        return [(index, self.materials.records[index].model) for index in self.materials.indices_of(kind)]

    # ---------------------------------------------------------------- evaluation
    def eval_pdf(
        self,
        material: Any,
        wi: Any,
        wo: Any,
        wavelengths: Any,
        coherence: IncidentCoherence,
        normal_world: Any,
        frame: Any,
        active: Any,
        wo_phase: Any = None,
    ) -> tuple[Any, Any]:
        """(f·cos θo per wavelength, hero-MIS pdf) for light arriving along ``wo``.

        ``wo_phase`` (default ``wo``) is the direction whose interference phase a thin film uses: for light
        from an emitter the direction to its centre (BRIEF: sampled emitter points serve radiometry only).
        """
        mi = self.mi
        kind = self.kind(material)
        value = mi.Spectrum(0.0)
        pdf = mi.Float(0.0)
        valid = active & (wi.z > 0) & (wo.z > 0)
        if mat.MaterialKind.DIFFUSE in self.kinds:
            is_kind = valid & (kind == int(mat.MaterialKind.DIFFUSE))
            reflectance = self.spectrum(material, mat.REFLECTANCE_ID, wavelengths)
            value = dr.select(is_kind, reflectance * (wo.z / math.pi), value)
            pdf = dr.select(is_kind, wo.z / math.pi, pdf)
        for index, surface in self._per_material(mat.MaterialKind.ROUGH_CONDUCTOR):
            is_this = valid & (material == index)
            fresnel = self.interface_reflectance(material, wi.z, wavelengths)
            lobe_value, lobe_pdf = self._rough_eval(surface, wi, wo, wavelengths, fresnel)
            value = dr.select(is_this, lobe_value, value)
            pdf = dr.select(is_this, lobe_pdf, pdf)
        for index, surface in self._per_material(mat.MaterialKind.THIN_FILM):
            is_this = valid & (material == index)
            terms = self.film_terms(material, (wo if wo_phase is None else wo_phase).z, wavelengths)
            thickness_m = self.param(material, mat.FILM_THICKNESS_M)
            film = combine_film_terms(
                terms,
                lambda d, t=thickness_m: self.visibility(coherence, normal_world * (t * d), wavelengths),
            )
            lobe_value, lobe_pdf = self._rough_eval(surface, wi, wo, wavelengths, film)
            value = dr.select(is_this, lobe_value, value)
            pdf = dr.select(is_this, lobe_pdf, pdf)
        for index, surface in self._per_material(mat.MaterialKind.ROUGH_DIELECTRIC):
            is_this = active & (material == index) & (wi.z != 0) & (wo.z != 0)
            d_value, d_pdf = self._rough_dielectric_eval(material, surface, wi, wo, wavelengths)
            value = dr.select(is_this, d_value, value)
            pdf = dr.select(is_this, d_pdf, pdf)
        for index, grating in self._per_material(mat.MaterialKind.GRATING):
            is_this = valid & (material == index)
            g_value, g_pdf = self._grating_eval(material, grating, wi, wo, wavelengths, coherence, frame)
            value = dr.select(is_this, g_value, value)
            pdf = dr.select(is_this, g_pdf, pdf)
        return value, pdf

    # ---------------------------------------------------------------- sampling
    def sample(
        self,
        material: Any,
        wi: Any,
        wavelengths: Any,
        sample1: Any,
        sample2: Any,
        active: Any,
        collapsed: Any = False,
    ):
        """(wo, weight = f·cos/pdf per wavelength, pdf, delta, film_terms, film_transmitted) for the next
        path segment.

        ``collapsed``: the path already refracted through a dispersive medium and carries its hero wavelength
        only (``_hero_collapse``); ``film_terms`` are the thin film's partially-coherent reflectance terms
        at the sampled direction —
        or its transmittance terms where ``film_transmitted`` (``combine_film_terms``); the weight uses
        their incoherent part, the integrator rescales it once the incident coherence is known.
        """
        mi = self.mi
        kind = self.kind(material)
        # (wo, weight, pdf, delta) of the branch each lane takes
        state = (mi.Vector3f(0.0, 0.0, 1.0), mi.Spectrum(0.0), mi.Float(0.0), mi.Bool(False))
        film_terms = [mi.Spectrum(0.0) for _ in range(self.max_beams)]
        front = active & (wi.z > 0)
        if mat.MaterialKind.DIFFUSE in self.kinds:
            direction = mi.warp.square_to_cosine_hemisphere(sample2)
            diffuse = (
                direction,
                self.spectrum(material, mat.REFLECTANCE_ID, wavelengths),
                mi.warp.square_to_cosine_hemisphere_pdf(direction),
                mi.Bool(False),
            )
            state = _take(front & (kind == int(mat.MaterialKind.DIFFUSE)), diffuse, state)
        if mat.MaterialKind.MIRROR in self.kinds:
            mirror = (
                mi.reflect(wi),
                self.interface_reflectance(material, wi.z, wavelengths),
                mi.Float(1.0),
                mi.Bool(True),
            )
            state = _take(front & (kind == int(mat.MaterialKind.MIRROR)), mirror, state)
        if mat.MaterialKind.DIELECTRIC in self.kinds:
            d_wo, d_weight = self._dielectric_sample(material, wi, wavelengths, sample1, collapsed)
            glass = (d_wo, d_weight, mi.Float(1.0), mi.Bool(True))
            state = _take(active & (kind == int(mat.MaterialKind.DIELECTRIC)), glass, state)
        for index, surface in self._per_material(mat.MaterialKind.ROUGH_CONDUCTOR):
            sampled = self._rough_sample(material, surface, wi, wavelengths, sample1, sample2, None)
            state = _take(front & (material == index), sampled, state)
        film_transmitted = mi.Bool(False)
        for index, surface in self._per_material(mat.MaterialKind.THIN_FILM):
            if self.materials.records[index].values.get(mat.FILM_TRANSMITS, 0.0) > 0.5:
                is_this = active & (material == index) & (wi.z != 0)
                sampled, terms, transmitted = self._coated_dielectric_sample(
                    material, surface, wi, wavelengths, sample1, sample2, collapsed
                )
                film_transmitted = dr.select(is_this, transmitted, film_transmitted)
            else:
                is_this = front & (material == index)
                terms_out: list = []
                sampled = self._rough_sample(material, surface, wi, wavelengths, sample1, sample2, terms_out)
                terms = terms_out[0]
            state = _take(is_this, sampled, state)
            for slot, term in enumerate(terms):
                film_terms[slot] = dr.select(is_this, term, film_terms[slot])
        for index, surface in self._per_material(mat.MaterialKind.ROUGH_DIELECTRIC):
            sampled = self._rough_dielectric_sample(
                material, surface, wi, wavelengths, sample1, sample2, collapsed
            )
            state = _take(active & (material == index) & (wi.z != 0), sampled, state)
        for index, grating in self._per_material(mat.MaterialKind.GRATING):
            sampled = self._grating_sample(material, grating, wi, wavelengths, sample1, sample2)
            state = _take(front & (material == index), sampled, state)
        wo, weight, pdf, delta = state
        return wo, dr.select(active, weight, 0.0), pdf, delta, film_terms, film_transmitted

    # ---------------------------------------------------------------- smooth dielectric
    def _dielectric_sample(self, material: Any, wi: Any, wavelengths: Any, sample1: Any, collapsed: Any):
        """Smooth dielectric (Dirac): reflect or refract with probability F of the hero wavelength.

        A dispersive index bends each wavelength differently, so after a refraction only the hero
        wavelength's path stays valid: its weight gains the factor 4 (its share of the four-wavelength pdf)
        and the others are zeroed — hero-wavelength spectral sampling. Radiance scales by 1/η² on refraction.
        """
        mi = self.mi
        eta = self.spectrum(material, mat.ETA_ID, wavelengths)[0] / self.param(material, mat.EXTERIOR_IOR)
        # η_ti = n_transmitted / n_incident seen from the camera side (inside: the inverse).
        eta_ti = dr.select(wi.z >= 0, eta, dr.rcp(eta))
        reflectance, cos_t = fresnel_dielectric(wi.z, eta_ti, OPS)
        reflect = sample1 <= reflectance
        wo = dr.select(reflect, mi.reflect(wi), _refract(mi, wi, eta_ti, cos_t))
        weight = self._hero_collapse(mi.Spectrum(1.0), material, ~reflect & ~collapsed)
        weight = dr.select(reflect, weight, weight * dr.square(dr.rcp(eta_ti)))
        return wo, weight

    def _hero_collapse(self, weight: Any, material: Any, refracted: Any) -> Any:
        """After a refraction through a dispersive medium only the hero wavelength's path is valid: its
        weight gains the factor 4 (its share of the four-wavelength pdf), the others are zeroed. Once per
        path: callers pass ``refracted & ~collapsed`` (a second factor 4 would bias the estimate 4×)."""
        collapse = refracted & (self.param(material, mat.DISPERSIVE) > 0.5)
        result = self.mi.Spectrum(weight)
        result[0] = dr.select(collapse, weight[0] * len(result), weight[0])
        for j in range(1, len(result)):
            result[j] = dr.select(collapse, 0.0, weight[j])
        return result

    # ---------------------------------------------------------------- thin film on a dielectric
    def _coated_dielectric_sample(
        self,
        material: Any,
        surface: rough_surface.RoughSurface,
        wi: Any,
        wavelengths: Any,
        sample1: Any,
        sample2: Any,
        collapsed: Any,
    ) -> tuple[tuple[Any, Any, Any, Any], list[Any], Any]:
        """A film on a dielectric substrate reflects with R(V) and transmits T(V) = 1 − R(V)
        (``thin_film.transmission_terms``): ((wo, weight, pdf, delta), film terms, transmitted).

        From the exterior (wi.z > 0) reflect with probability R_incoherent(λ_hero), as the rough film does
        (specular part and Eq. 15 lobe), else refract specularly into the substrate; from the substrate
        the exterior-side angle follows from n_s sin θ_s = n_0 sin θ_0 through the stack (beyond the
        critical angle all light is reflected) and reflection and transmission are specular. A lossless
        stack has the same R from both sides (exact in the coherent and incoherent limits), so the
        exterior-side terms serve both. The film's roughness scatters reflected light only.
        """
        mi = self.mi
        exterior = self.param(material, mat.EXTERIOR_IOR)
        eta = self.spectrum(material, mat.ETA_ID, wavelengths)[0] / exterior
        outside = wi.z > 0
        eta_ti = dr.select(outside, eta, dr.rcp(eta))  # n_transmitted / n_incident (hero)
        _, cos_t = fresnel_dielectric(wi.z, eta_ti, OPS)
        cos_i = dr.abs(wi.z)
        total_internal = ~outside & (dr.square(eta_ti) < 1.0 - dr.square(cos_i))
        cos_exterior = dr.select(outside, cos_i, cos_t)
        terms = self.film_terms(material, cos_exterior, wavelengths)
        reflectance = dr.select(total_internal, 1.0, terms[0])
        reflect_probability = reflectance[0]
        reflect = sample1 < reflect_probability
        # exterior reflection: the rough film's own sampling with the remaining uniform
        lobe_terms: list = []
        u_reflect = dr.clip(sample1 / dr.maximum(reflect_probability, 1e-12), 0.0, 0.999999)
        r_wo, r_weight, r_pdf, r_delta = self._rough_sample(
            material, surface, wi, wavelengths, u_reflect, sample2, lobe_terms
        )
        r_weight = r_weight / dr.maximum(reflect_probability, 1e-12)
        # substrate-side reflection: specular, R/R_hero
        inner_weight = reflectance / dr.maximum(reflect_probability, 1e-12)
        # transmission: specular refraction with T/T_hero and the radiance factor (n_camera/n_light)²
        transmittance = 1.0 - reflectance
        t_weight = transmittance / dr.maximum(1.0 - reflect_probability, 1e-12) * dr.square(dr.rcp(eta_ti))
        t_weight = self._hero_collapse(t_weight, material, ~collapsed)
        wo = dr.select(reflect, dr.select(outside, r_wo, mi.reflect(wi)), _refract(mi, wi, eta_ti, cos_t))
        weight = dr.select(reflect, dr.select(outside, r_weight, inner_weight), t_weight)
        pdf = dr.select(reflect & outside, r_pdf, 1.0)
        delta = dr.select(reflect & outside, r_delta, True)
        no_interference = [mi.Spectrum(1.0 if slot == 0 else 0.0) for slot in range(len(terms))]
        inner_terms = [dr.select(total_internal, a, b) for a, b in zip(no_interference, terms, strict=True)]
        reflected_terms = [dr.select(outside, a, b) for a, b in zip(lobe_terms[0], inner_terms, strict=True)]
        transmitted = ~reflect
        chosen = [
            dr.select(transmitted, a, b)
            for a, b in zip(transmission_terms(terms), reflected_terms, strict=True)
        ]
        return (wo, weight, pdf, delta), chosen, transmitted

    # ---------------------------------------------------------------- rough statistical surface (Eq. 15)
    def _rough_eval(
        self, surface: rough_surface.RoughSurface, wi: Any, wo: Any, wavelengths: Any, reflectance: Any
    ) -> tuple[Any, Any]:
        """Scattered lobe value f·cos θo and hero-MIS pdf for light arriving along ``wo``.

        Harvey–Shack's incident-side factors (1 − e^{−g}, the propagating fraction) are those of the side
        the path arrives from, ``wi`` (``rough_surface``: the model is not reciprocal; this choice gives the
        estimator the albedo F exactly). ``reflectance`` is the caller's F (conductors: at ``wi``).
        """
        mi = self.mi
        value = mi.Spectrum(0.0)
        pdf_sum = mi.Float(0.0)
        light, view = _vec(wo), _vec(wi)
        sin_view = dr.sqrt(dr.maximum(wi.x * wi.x + wi.y * wi.y, 0.0))
        for j in range(len(wavelengths)):
            wavelength_m = wavelengths[j] * 1e-9
            fraction = self._reflection_fraction(surface, sin_view, wavelengths[j])
            brdf = rough_surface.rough_reflection_eval(
                surface, view, light, wavelength_m, reflectance[j], OPS, fraction=fraction
            )
            value[j] = brdf * wo.z
            pdf_sum += rough_surface.rough_reflection_pdf(surface, view, light, wavelength_m, OPS)
        return value, pdf_sum / len(wavelengths)

    def _reflection_fraction(
        self, surface: rough_surface.RoughSurface, sin_theta: Any, wavelength_nm: Any
    ) -> Any:
        """Propagating fraction P of reflection in air, bilinear in ``reflection_fraction_table`` (built once
        per surface): 4 gathers instead of a 32-node angular integral per wavelength and sample."""
        mi = self.mi
        key = id(surface)
        if key not in self._fraction_tables:
            table = rough_surface.reflection_fraction_table(surface).ravel()
            self._fraction_tables[key] = (surface, mi.Float(table))
        table = self._fraction_tables[key][1]
        columns = len(rough_surface.TABLE_WAVELENGTHS_M)
        first = float(rough_surface.TABLE_WAVELENGTHS_M[0]) * 1e9
        last = float(rough_surface.TABLE_WAVELENGTHS_M[-1]) * 1e9
        # Invert sin θ = 1 − (1 − x)², then cell coordinates along both axes.
        x = 1.0 - dr.sqrt(dr.maximum(1.0 - sin_theta, 0.0))
        rows = rough_surface.TABLE_ANGLE_NODES
        row_f = dr.clip(x * (rows - 1), 0.0, rows - 1.001)
        column_f = dr.clip((wavelength_nm - first) / (last - first) * (columns - 1), 0.0, columns - 1.001)
        row, column = mi.UInt32(row_f), mi.UInt32(column_f)
        a, b = row_f - mi.Float(row), column_f - mi.Float(column)

        def at(r: Any, c: Any) -> Any:
            return dr.gather(mi.Float, table, r * columns + c)

        top = at(row, column) * (1.0 - b) + at(row, column + 1) * b
        bottom = at(row + 1, column) * (1.0 - b) + at(row + 1, column + 1) * b
        return top * (1.0 - a) + bottom * a

    def film_terms(self, material: Any, cos_i: Any, wavelengths: Any) -> list[Any]:
        """[R_incoherent, X_1 … X_{P−1}] per wavelength (``combine_film_terms``) at incidence cos_i."""
        mi = self.mi
        exterior = self.param(material, mat.EXTERIOR_IOR)
        thickness_m = self.param(material, mat.FILM_THICKNESS_M)
        film_ior = self.spectrum(material, mat.FILM_IOR_ID, wavelengths)
        substrate_n = self.spectrum(material, mat.ETA_ID, wavelengths)
        substrate_k = self.spectrum(material, mat.KAPPA_ID, wavelengths)
        terms = [mi.Spectrum(0.0) for _ in range(self.max_beams)]
        for j in range(len(wavelengths)):
            amplitudes = film_amplitudes(
                cos_i,
                wavelengths[j] * 1e-9,
                thickness_m,
                film_ior[j],
                ComplexPair(substrate_n[j], substrate_k[j]),
                exterior,
                self.max_beams,
                OPS,
            )
            for slot, term in enumerate(reflectance_terms(amplitudes)):
                terms[slot][j] = term
        return terms

    def _rough_sample(
        self,
        material: Any,
        surface: rough_surface.RoughSurface,
        wi: Any,
        wavelengths: Any,
        sample1: Any,
        sample2: Any,
        film_terms_out: list | None,
    ):
        """Specular (delta) part with probability ⟨e^{−g}⟩ (the mean over the path's wavelengths), else an
        exact PSD-lobe sample at λ_hero.

        The specular fraction e^{−g} varies by orders of magnitude across the spectrum (g ∝ 1/λ²); choosing
        by the hero's alone would give the other wavelengths weights up to e^{g_hero − g_j} (fireflies).
        The mean is a one-sample MIS over the wavelengths: every weight is at most 4·F_j/F.

        For a thin film (``film_terms_out`` given) the interface reflectance is the film's incoherent
        reflectance at the sampled direction; its terms are appended to ``film_terms_out``.
        """
        mi = self.mi
        view = _vec(wi)
        hero_m = wavelengths[0] * 1e-9
        specular_probability = _mean_over_wavelengths(
            [
                dr.exp(-rough_surface.roughness_exponent(surface.rms_height_m, wi.z, wavelengths[j] * 1e-9))
                for j in range(len(wavelengths))
            ]
        )
        choose_specular = sample1 < specular_probability
        lobe_sample1 = dr.clip(
            (sample1 - specular_probability) / dr.maximum(1.0 - specular_probability, 1e-12), 0.0, 0.999999
        )
        lobe_dir, _, lobe_valid = rough_surface.rough_reflection_sample(
            surface, view, hero_m, lobe_sample1, sample2[0], OPS
        )
        lobe_wo = mi.Vector3f(*lobe_dir)
        wo = dr.select(choose_specular, mi.reflect(wi), lobe_wo)
        if film_terms_out is None:
            reflectance = self.interface_reflectance(material, wi.z, wavelengths)
        else:
            terms = self.film_terms(material, wo.z, wavelengths)
            film_terms_out.append(terms)
            reflectance = terms[0]
        lobe_value, lobe_pdf = self._rough_eval(surface, wi, lobe_wo, wavelengths, reflectance)
        lobe_weight = lobe_value / dr.maximum(lobe_pdf * (1.0 - specular_probability), 1e-20)
        specular_weight = mi.Spectrum(0.0)
        for j in range(len(wavelengths)):
            g_j = rough_surface.roughness_exponent(surface.rms_height_m, wi.z, wavelengths[j] * 1e-9)
            specular_weight[j] = reflectance[j] * dr.exp(-g_j) / dr.maximum(specular_probability, 1e-20)
        weight = dr.select(
            choose_specular, specular_weight, dr.select(lobe_valid & (lobe_pdf > 0), lobe_weight, 0.0)
        )
        pdf = dr.select(choose_specular, 1.0, lobe_pdf)
        return wo, weight, pdf, choose_specular

    # ---------------------------------------------------------------- rough dielectric (Eq. 15, two sides)
    def _camera_side(self, material: Any, wi: Any, wavelengths: Any) -> tuple[Any, Any, Any]:
        """(outside, n_camera, n_other) per wavelength: relative indices of the camera's and the far side."""
        eta = self.spectrum(material, mat.ETA_ID, wavelengths) / self.param(material, mat.EXTERIOR_IOR)
        outside = wi.z > 0
        return outside, dr.select(outside, 1.0, eta), dr.select(outside, eta, 1.0)

    def _rough_dielectric_eval(
        self, material: Any, surface: rough_surface.RoughSurface, wi: Any, wo: Any, wavelengths: Any
    ) -> tuple[Any, Any]:
        """f·|cos θo| and hero-MIS pdf of the rough interface's scattered lobes (light arriving along wo).

        Directions are mirrored so that the camera side is +z, and the camera side is Harvey–Shack's
        incident side (as in ``_rough_eval``). Reflection: the renormalised Eq. 15 lobe in the camera's medium
        with the dielectric Fresnel R(θ_view); transmission: the renormalised transmitted lobe with
        T = 1 − R(θ_view) times the radiance factor (n_camera/n_light)² of non-symmetric transport. Each lobe
        then carries exactly R(1 − e^{−g}) and T(1 − e^{−g_t}): with the specular parts the interface
        returns R + T = 1 (white furnace). The pdf is that of ``_rough_dielectric_sample`` (selection
        probability × lobe density), so a lobe sample's weight is a constant.
        """
        mi = self.mi
        outside, n_camera, n_other = self._camera_side(material, wi, wavelengths)
        side = dr.select(outside, 1.0, -1.0)
        view = mi.Vector3f(wi.x, wi.y, wi.z * side)
        light = mi.Vector3f(wo.x, wo.y, wo.z * side)
        reflected = light.z > 0
        value = mi.Spectrum(0.0)
        pdf_sum = mi.Float(0.0)
        for j in range(len(wavelengths)):
            wavelength_m = wavelengths[j] * 1e-9
            r_view, cos_t_view = fresnel_dielectric(view.z, n_other[j] / n_camera[j], OPS)
            # Beyond the critical angle T is 0, not the float32 rounding of 1 − R (which the lobe's
            # renormalisation over a vanishing propagating fraction would amplify into fireflies).
            t_view = dr.select(cos_t_view > 0.0, 1.0 - r_view, 0.0)
            reflection = rough_surface.rough_reflection_eval(
                surface, _vec(view), _vec(light), wavelength_m, r_view, OPS, exterior_ior=n_camera[j]
            )
            reflection_pdf = rough_surface.rough_reflection_pdf(
                surface, _vec(view), _vec(light), wavelength_m, OPS, exterior_ior=n_camera[j]
            )
            transmission = rough_surface.rough_transmission_eval(
                surface,
                _vec(view),
                _vec(light),
                wavelength_m,
                t_view,
                cos_t_view,
                OPS,
                exterior_ior=n_camera[j],
                interior_ior=n_other[j],
            ) * dr.square(n_camera[j] / n_other[j])
            transmission_pdf = rough_surface.rough_transmission_pdf(
                surface,
                _vec(view),
                _vec(light),
                wavelength_m,
                OPS,
                exterior_ior=n_camera[j],
                interior_ior=n_other[j],
            )
            value[j] = dr.select(reflected, reflection, transmission) * dr.abs(light.z)
            pdf_sum += dr.select(reflected, r_view * reflection_pdf, t_view * transmission_pdf)
        return value, pdf_sum / len(wavelengths)

    def _rough_dielectric_sample(
        self,
        material: Any,
        surface: rough_surface.RoughSurface,
        wi: Any,
        wavelengths: Any,
        sample1: Any,
        sample2: Any,
        collapsed: Any,
    ) -> tuple[Any, Any, Any, Any]:
        """Reflect with probability R(λ_hero) else transmit; within each, the specular (delta) part with
        probability e^{−g}, else an exact PSD-lobe sample. Dispersive media keep the hero wavelength only
        after a specular refraction (as the smooth dielectric does); radiance scales by (n_camera/n_light)²
        across the interface."""
        mi = self.mi
        outside, n_camera, n_other = self._camera_side(material, wi, wavelengths)
        side = dr.select(outside, 1.0, -1.0)
        view = mi.Vector3f(wi.x, wi.y, wi.z * side)
        hero_m = wavelengths[0] * 1e-9
        eta_hero = n_other[0] / n_camera[0]
        reflectance_hero, cos_t_hero = fresnel_dielectric(view.z, eta_hero, OPS)
        reflect = sample1 < reflectance_hero
        u = dr.select(
            reflect,
            sample1 / dr.maximum(reflectance_hero, 1e-12),
            (sample1 - reflectance_hero) / dr.maximum(1.0 - reflectance_hero, 1e-12),
        )
        u = dr.clip(u, 0.0, 0.999999)
        # Specular fraction: the mean of e^{−g} over the wavelengths (see ``_rough_sample``).
        specular_fractions = []
        for j in range(len(wavelengths)):
            wavelength_m = wavelengths[j] * 1e-9
            _, cos_t_j = fresnel_dielectric(view.z, n_other[j] / n_camera[j], OPS)
            g_reflect = rough_surface.roughness_exponent(
                surface.rms_height_m, view.z, wavelength_m, n_camera[j]
            )
            g_transmit = rough_surface.transmission_roughness_exponent(
                surface.rms_height_m, view.z, cos_t_j, wavelength_m, n_camera[j], n_other[j]
            )
            specular_fractions.append(dr.exp(-dr.select(reflect, g_reflect, g_transmit)))
        specular_probability = _mean_over_wavelengths(specular_fractions)
        specular = u < specular_probability
        u_lobe = dr.clip(
            (u - specular_probability) / dr.maximum(1.0 - specular_probability, 1e-12), 0.0, 0.999999
        )
        lobe_r, _, valid_r = rough_surface.rough_reflection_sample(
            surface, _vec(view), hero_m, u_lobe, sample2[0], OPS, exterior_ior=n_camera[0]
        )
        lobe_t, _, valid_t = rough_surface.rough_transmission_sample(
            surface,
            _vec(view),
            hero_m,
            u_lobe,
            sample2[0],
            OPS,
            exterior_ior=n_camera[0],
            interior_ior=n_other[0],
        )
        lobe = mi.Vector3f(*(dr.select(reflect, a, b) for a, b in zip(lobe_r, lobe_t, strict=True)))
        lobe_valid = dr.select(reflect, valid_r, valid_t)
        refracted = mi.Vector3f(-view.x / eta_hero, -view.y / eta_hero, -cos_t_hero)
        specular_dir = dr.select(reflect, mi.reflect(view), refracted)
        local = dr.select(specular, specular_dir, lobe)
        wo = mi.Vector3f(local.x, local.y, local.z * side)
        # Lobe sample: the estimator's weight is value / pdf of the same formulation as eval_pdf.
        lobe_value, lobe_pdf = self._rough_dielectric_eval(material, surface, wi, wo, wavelengths)
        lobe_weight = lobe_value / dr.maximum(lobe_pdf * (1.0 - specular_probability), 1e-20)
        # Specular sample: R e^{−g} (or T e^{−g_t} with the radiance factor) over its selection probability.
        specular_weight = mi.Spectrum(0.0)
        for j in range(len(wavelengths)):
            wavelength_m = wavelengths[j] * 1e-9
            eta_j = n_other[j] / n_camera[j]
            r_j, cos_t_j = fresnel_dielectric(view.z, eta_j, OPS)
            g_r = rough_surface.roughness_exponent(surface.rms_height_m, view.z, wavelength_m, n_camera[j])
            g_t = rough_surface.transmission_roughness_exponent(
                surface.rms_height_m, view.z, cos_t_j, wavelength_m, n_camera[j], n_other[j]
            )
            reflected_part = r_j * dr.exp(-g_r) / dr.maximum(reflectance_hero * specular_probability, 1e-20)
            transmitted_part = (
                (1.0 - r_j)
                * dr.exp(-g_t)
                * dr.square(n_camera[j] / n_other[j])
                / dr.maximum((1.0 - reflectance_hero) * specular_probability, 1e-20)
            )
            specular_weight[j] = dr.select(reflect, reflected_part, transmitted_part)
        specular_weight = self._hero_collapse(specular_weight, material, specular & ~reflect & ~collapsed)
        weight = dr.select(
            specular, specular_weight, dr.select(lobe_valid & (lobe_pdf > 0), lobe_weight, 0.0)
        )
        pdf = dr.select(specular, 1.0, lobe_pdf)
        return wo, weight, pdf, specular

    # ---------------------------------------------------------------- grating (Eq. 20)
    def _grating_axes(self, material: Any, frame: Any) -> tuple[Any, Any]:
        angle = self.param(material, mat.ORIENTATION_RAD)
        cos_a, sin_a = dr.cos(angle), dr.sin(angle)
        return frame.s * cos_a + frame.t * sin_a, frame.t * cos_a - frame.s * sin_a

    def _to_grating(self, material: Any, v: Any) -> Any:
        angle = self.param(material, mat.ORIENTATION_RAD)
        cos_a, sin_a = dr.cos(angle), dr.sin(angle)
        return self.mi.Vector3f(cos_a * v.x + sin_a * v.y, -sin_a * v.x + cos_a * v.y, v.z)

    def _from_grating(self, material: Any, v: Any) -> Any:
        angle = self.param(material, mat.ORIENTATION_RAD)
        cos_a, sin_a = dr.cos(angle), dr.sin(angle)
        return self.mi.Vector3f(cos_a * v.x - sin_a * v.y, sin_a * v.x + cos_a * v.y, v.z)

    def _angular_covariance(
        self, material: Any, coherence: IncidentCoherence, frame: Any
    ) -> tuple[Any, Any, Any]:
        """Σ'/s²: the incident Σ⊥ projected on the grating plane (grating axes) over the squared distance."""
        axis_u, axis_v = self._grating_axes(material, frame)
        a, b = dr.dot(axis_u, coherence.frame_x), dr.dot(axis_u, coherence.frame_y)
        c, d = dr.dot(axis_v, coherence.frame_x), dr.dot(axis_v, coherence.frame_y)
        sxx, sxy, syy = coherence.sigma_xx, coherence.sigma_xy, coherence.sigma_yy
        inv_r2 = dr.rcp(dr.square(dr.maximum(coherence.distance_m, 1e-9)))
        return (
            (a * a * sxx + 2 * a * b * sxy + b * b * syy) * inv_r2,
            (a * c * sxx + (a * d + b * c) * sxy + b * d * syy) * inv_r2,
            (c * c * sxx + 2 * c * d * sxy + d * d * syy) * inv_r2,
        )

    def _grating_eval(
        self,
        material: Any,
        grating: grating_model.BinaryGrating,
        wi: Any,
        wo: Any,
        wavelengths: Any,
        coherence: IncidentCoherence,
        frame: Any,
    ) -> tuple[Any, Any]:
        mi = self.mi
        light, view = _vec(self._to_grating(material, wo)), _vec(self._to_grating(material, wi))
        angular_cov = self._angular_covariance(material, coherence, frame)
        fresnel = self.interface_reflectance(material, wo.z, wavelengths)
        value = mi.Spectrum(0.0)
        pdf_sum = mi.Float(0.0)
        for j in range(len(wavelengths)):
            wavelength_m = wavelengths[j] * 1e-9
            brdf = grating_model.grating_eval(
                grating, light, view, wavelength_m, fresnel[j], angular_cov, OPS
            )
            value[j] = brdf * wo.z
            pdf_sum += grating_model.grating_pdf(grating, view, light, wavelength_m, angular_cov, OPS)
        return value, pdf_sum / len(wavelengths)

    def _grating_sample(
        self,
        material: Any,
        grating: grating_model.BinaryGrating,
        wi: Any,
        wavelengths: Any,
        sample1: Any,
        sample2: Any,
    ):
        """The 0th order (specular, coherence kept) with probability η_00(λ_hero), else a diffraction lobe.

        Lobes are drawn with the intrinsic lobe width only: the coherence of indirect light is not known
        when the direction is chosen, and direct light reaches gratings through next-event estimation only
        (docs/integrator.md).
        """
        mi = self.mi
        view = _vec(self._to_grating(material, wi))
        hero_m = wavelengths[0] * 1e-9
        zero_cov = (mi.Float(0.0), mi.Float(0.0), mi.Float(0.0))
        specular_probability = grating_model.specular_efficiency(grating, hero_m, OPS)
        choose_specular = sample1 < specular_probability
        order_sample = dr.clip(
            (sample1 - specular_probability) / dr.maximum(1.0 - specular_probability, 1e-12), 0.0, 0.999999
        )
        lobe_dir, _, lobe_valid, _ = grating_model.grating_sample(
            grating, view, hero_m, zero_cov, order_sample, sample2[0], sample2[1], OPS
        )
        lobe_wo = self._from_grating(material, mi.Vector3f(*lobe_dir))
        wo = dr.select(choose_specular, mi.reflect(wi), lobe_wo)
        fresnel = self.interface_reflectance(material, wo.z, wavelengths)
        lobe_value = mi.Spectrum(0.0)
        pdf_sum = mi.Float(0.0)
        specular_weight = mi.Spectrum(0.0)
        light = _vec(self._to_grating(material, lobe_wo))
        for j in range(len(wavelengths)):
            wavelength_m = wavelengths[j] * 1e-9
            brdf = grating_model.grating_eval(grating, light, view, wavelength_m, fresnel[j], zero_cov, OPS)
            lobe_value[j] = brdf * lobe_wo.z
            pdf_sum += grating_model.grating_pdf(grating, view, light, wavelength_m, zero_cov, OPS)
            eta_00 = grating_model.specular_efficiency(grating, wavelength_m, OPS)
            specular_weight[j] = fresnel[j] * eta_00 / dr.maximum(specular_probability, 1e-20)
        lobe_pdf = pdf_sum / len(wavelengths)
        lobe_weight = lobe_value / dr.maximum(lobe_pdf * (1.0 - specular_probability), 1e-20)
        weight = dr.select(
            choose_specular, specular_weight, dr.select(lobe_valid & (lobe_pdf > 0), lobe_weight, 0.0)
        )
        pdf = dr.select(choose_specular, 1.0, lobe_pdf)
        return wo, weight, pdf, choose_specular


def _mean_over_wavelengths(values: list[Any]) -> Any:
    total = values[0]
    for value in values[1:]:
        total = total + value
    return total / len(values)


def _refract(mi: Any, wi: Any, eta_ti: Any, cos_t: Any) -> Any:
    """Snell refraction of ``wi`` (local frame) with relative index η_ti = n_t/n_i and |cos θ_t|."""
    return mi.Vector3f(-wi.x / eta_ti, -wi.y / eta_ti, -dr.mulsign(cos_t, wi.z))


def _take(mask: Any, sampled: tuple, state: tuple) -> tuple:
    """Per lane, the sample (wo, weight, pdf, delta) of the material branch selected by ``mask``."""
    return tuple(dr.select(mask, new, old) for new, old in zip(sampled, state, strict=True))


def combine_film_terms(terms: list[Any], visibility_at: Callable[[int], Any]) -> Any:
    """R(V) of the partially coherent multi-beam sum, V_d = ``visibility_at(d)`` (Eq. 18 for P = 2)."""
    visibilities = [visibility_at(separation) for separation in range(1, len(terms))]
    return dr.maximum(combine_reflectance_terms(terms, visibilities), 0.0)
