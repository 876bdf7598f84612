"""Smooth dielectric (Dirac): reflect or refract with probability F of the hero wavelength.

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

    def sample_domain(self, wi: mi.Vector3f, active: mi.Bool) -> mi.Bool:
        return active  # both sides: the interface transmits

    def sample(self, point: ShadingPoint, sample1: mi.Float, sample2: mi.Point2f) -> MaterialSample:
        params, material, wi, wavelengths = self.params, point.material, point.wi, point.wavelengths
        eta = params.spectrum(material, mat.ETA_ID, wavelengths)[0] / params.param(material, mat.EXTERIOR_IOR)
        # η_ti = n_transmitted / n_incident seen from the camera side (inside: the inverse).
        eta_ti = dr.select(wi.z >= 0, eta, dr.rcp(eta))
        reflectance, cos_t = fresnel_dielectric(wi.z, eta_ti, OPS)
        reflect = sample1 <= reflectance
        wo = dr.select(reflect, mi.reflect(wi), refract(wi, eta_ti, cos_t))
        weight = params.hero_collapse(mi.Spectrum(1.0), material, ~reflect & ~point.collapsed)
        weight = dr.select(reflect, weight, weight * dr.square(dr.rcp(eta_ti)))
        return MaterialSample(wo, weight, mi.Float(1.0), mi.Bool(True), dr.select(reflect, 1.0, eta_ti))
