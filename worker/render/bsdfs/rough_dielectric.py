"""Rough dielectric interface: Eq. 15 on both sides (Harvey–Shack reflection and transmission).

Directions are mirrored so that the camera side is +z, and the camera side is Harvey–Shack's incident side
(as for ``rough_conductor``). Reflection: the renormalised Eq. 15 lobe in the camera's medium with the
dielectric Fresnel R(θ_view); transmission: the renormalised transmitted lobe with T = 1 − R(θ_view) times
the radiance factor (n_camera/n_light)² of non-symmetric transport. Each lobe then carries exactly
R(1 − e^{−g}) and T(1 − e^{−g_t}): with the specular parts the interface returns R + T = 1 (white furnace).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from hgcore.optics import rough_surface
from hgcore.optics.fresnel import fresnel_dielectric
from worker.render import materials as mat
from worker.render.bsdfs.common import OPS, IncidentCoherence, Material, MaterialSample, ShadingPoint, vec
from worker.render.bsdfs.lobes import mean_over_wavelengths, specular_or_lobe, split_specular


class RoughDielectric(Material):
    kind = mat.MaterialKind.ROUGH_DIELECTRIC
    per_material = True
    spectra = (mat.ETA_ID,)
    model: rough_surface.RoughSurface

    def sample_domain(self, wi: mi.Vector3f, active: mi.Bool) -> mi.Bool:
        return active & (wi.z != 0)

    def eval_domain(self, wi: mi.Vector3f, wo: mi.Vector3f, active: mi.Bool) -> mi.Bool:
        return active & (wi.z != 0) & (wo.z != 0)

    def _camera_side(self, point: ShadingPoint) -> tuple[mi.Bool, mi.Spectrum, mi.Spectrum]:
        """(outside, n_camera, n_other) per wavelength: relative indices of the camera's and the far side."""
        params, material = self.params, point.material
        eta = point.spectra[mat.ETA_ID] / params.param(material, mat.EXTERIOR_IOR)
        outside = point.wi.z > 0
        return outside, dr.select(outside, 1.0, eta), dr.select(outside, eta, 1.0)

    def eval_pdf(
        self, point: ShadingPoint, wo: mi.Vector3f, coherence: IncidentCoherence, wo_phase: mi.Vector3f
    ) -> tuple[mi.Spectrum, mi.Spectrum]:
        return self.lobes(point, wo)

    def lobes(self, point: ShadingPoint, wo: mi.Vector3f) -> tuple[mi.Spectrum, mi.Spectrum]:
        """f·|cos θo| and per-wavelength densities p_k of the scattered lobes (light arriving along wo). p_k
        is that of ``sample`` with hero λ_k (selection probability R_k or T_k × lobe density), so a lobe
        sample's weight is a constant."""
        surface, wi, wavelengths = self.surface(point), point.wi, point.wavelengths
        outside, n_camera, n_other = self._camera_side(point)
        side = dr.select(outside, 1.0, -1.0)
        view = mi.Vector3f(wi.x, wi.y, wi.z * side)
        light = mi.Vector3f(wo.x, wo.y, wo.z * side)
        reflected = light.z > 0
        value = mi.Spectrum(0.0)
        pdfs = mi.Spectrum(0.0)
        for j in range(len(wavelengths)):
            wavelength_m = wavelengths[j] * 1e-9
            r_view, cos_t_view = fresnel_dielectric(view.z, n_other[j] / n_camera[j], OPS)
            # Beyond the critical angle T is 0, not the float32 rounding of 1 − R (which the lobe's
            # renormalisation over a vanishing propagating fraction would amplify into fireflies).
            t_view = dr.select(cos_t_view > 0.0, 1.0 - r_view, 0.0)
            reflection = rough_surface.rough_reflection_eval(
                surface,
                vec(view),
                vec(light),
                wavelength_m,
                r_view,
                OPS,
                exterior_ior=n_camera[j],
            )
            reflection_pdf = rough_surface.rough_reflection_pdf(
                surface, vec(view), vec(light), wavelength_m, OPS, exterior_ior=n_camera[j]
            )
            transmission = rough_surface.rough_transmission_eval(
                surface,
                vec(view),
                vec(light),
                wavelength_m,
                t_view,
                cos_t_view,
                OPS,
                exterior_ior=n_camera[j],
                interior_ior=n_other[j],
            ) * dr.square(n_camera[j] / n_other[j])
            transmission_pdf = rough_surface.rough_transmission_pdf(
                surface,
                vec(view),
                vec(light),
                wavelength_m,
                OPS,
                exterior_ior=n_camera[j],
                interior_ior=n_other[j],
            )
            value[j] = dr.select(reflected, reflection, transmission) * dr.abs(light.z)
            pdfs[j] = dr.select(reflected, r_view * reflection_pdf, t_view * transmission_pdf)
        return value, pdfs

    def sample(self, point: ShadingPoint, sample1: mi.Float, sample2: mi.Point2f) -> MaterialSample:
        """Reflect with probability R(λ_hero) else transmit; within each, the specular (delta) part with
        probability ⟨e^{−g}⟩ (the mean over the wavelengths, as for ``rough_conductor``), else an exact
        PSD-lobe sample. Dispersive media keep the hero wavelength only after a specular refraction (as
        the smooth dielectric does); radiance scales by (n_camera/n_light)² across the interface. The pdf
        ratios q_k (``common``): R_k/R_hero (T_k/T_hero) for the specular part, p_k/p̄ for the lobe (its
        p_k already hold R_k or T_k)."""
        surface, wi, wavelengths = self.surface(point), point.wi, point.wavelengths
        outside, n_camera, n_other = self._camera_side(point)
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
        specular_probability = mean_over_wavelengths(specular_fractions)
        specular, u_lobe = split_specular(u, specular_probability)
        lobe_r, _, valid_r = rough_surface.rough_reflection_sample(
            surface, vec(view), hero_m, u_lobe, sample2[0], OPS, exterior_ior=n_camera[0]
        )
        lobe_t, _, valid_t = rough_surface.rough_transmission_sample(
            surface,
            vec(view),
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
        lobe_value, lobe_pdfs = self.lobes(point, wo)
        # Specular sample: R e^{−g} (or T e^{−g_t} with the radiance factor) over its selection probability.
        specular_weight = mi.Spectrum(0.0)
        specular_ratios = mi.Spectrum(0.0)  # hero k reflects with R_k, transmits with 1 − R_k
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
            specular_ratios[j] = dr.select(
                reflect,
                r_j / dr.maximum(reflectance_hero, 1e-12),
                (1.0 - r_j) / dr.maximum(1.0 - reflectance_hero, 1e-12),
            )
        specular_weight, specular_ratios = self.params.hero_collapse(
            specular_weight, specular_ratios, point.material, specular & ~reflect
        )
        # Russian roulette divides out the radiance factor of a transmission (η of the hero wavelength).
        eta = dr.select(reflect, 1.0, eta_hero)
        lobe = (lobe_value, lobe_pdfs, lobe_valid)
        return specular_or_lobe(
            specular, specular_probability, wo, specular_weight, *lobe, eta, specular_ratios
        )
