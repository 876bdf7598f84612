"""Smooth dielectric (Dirac): reflect or refract with probability F of the hero wavelength (weights
F_j/F_hero, pdf ratios F_k/F_hero for the path-level hero MIS; the same for T = 1 − F).

A dispersive index bends each wavelength differently, so after a refraction only the hero wavelength's
path stays valid (``MaterialParams.hero_collapse``). Radiance scales by 1/η² on refraction (non-symmetric
transport, η = n_transmitted/n_incident).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from hgcore.optics.fresnel import fresnel_dielectric
from worker.render import materials as mat
from worker.render.bsdfs.common import OPS, Material, MaterialSample, ShadingPoint, refract


class Dielectric(Material):
    kind = mat.MaterialKind.DIELECTRIC
    spectra = (mat.ETA_ID,)

    def sample_domain(self, wi: mi.Vector3f, active: mi.Bool) -> mi.Bool:
        return active  # both sides: the interface transmits

    def sample(self, point: ShadingPoint, sample1: mi.Float, sample2: mi.Point2f) -> MaterialSample:
        params, material, wi, wavelengths = self.params, point.material, point.wi, point.wavelengths
        eta = point.spectra[mat.ETA_ID] / params.param(material, mat.EXTERIOR_IOR)
        # η_ti = n_transmitted / n_incident seen from the camera side (inside: the inverse), per wavelength.
        eta_ti = dr.select(wi.z >= 0, eta, dr.rcp(eta))
        reflectance = mi.Spectrum(0.0)
        for j in range(len(wavelengths)):
            reflectance[j], _ = fresnel_dielectric(wi.z, eta_ti[j], OPS)
        _, cos_t = fresnel_dielectric(wi.z, eta_ti[0], OPS)
        # Reflect with the hero's R: weight R_j/R_hero, and hero k would have chosen it with R_k (q_k).
        reflect = sample1 <= reflectance[0]
        chosen = dr.select(reflect, reflectance, 1.0 - reflectance)
        chosen_hero = dr.maximum(chosen[0], 1e-12)
        weight = chosen / chosen_hero
        ratios = chosen / chosen_hero
        wo = dr.select(reflect, mi.reflect(wi), refract(wi, eta_ti[0], cos_t))
        weight, ratios = params.hero_collapse(weight, ratios, material, ~reflect)
        weight = dr.select(reflect, weight, weight * dr.square(dr.rcp(eta_ti)))
        eta_sampled = dr.select(reflect, 1.0, eta_ti[0])
        return MaterialSample(wo, weight, mi.Spectrum(1.0), mi.Bool(True), eta_sampled, pdf_ratios=ratios)
