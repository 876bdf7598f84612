"""Lambertian reflector: f = ρ(λ)/π, cosine-weighted sampling (weight ρ, pdf cos θo/π)."""

from __future__ import annotations

import math

import mitsuba as mi

from worker.render import materials as mat
from worker.render.bsdfs.common import IncidentCoherence, Material, MaterialSample


class Diffuse(Material):
    kind = mat.MaterialKind.DIFFUSE

    def sample(
        self,
        material: mi.UInt32,
        wi: mi.Vector3f,
        wavelengths: mi.Spectrum,
        sample1: mi.Float,
        sample2: mi.Point2f,
        collapsed: mi.Bool,
    ) -> MaterialSample:
        direction = mi.warp.square_to_cosine_hemisphere(sample2)
        return MaterialSample(
            direction,
            self.params.spectrum(material, mat.REFLECTANCE_ID, wavelengths),
            mi.warp.square_to_cosine_hemisphere_pdf(direction),
            mi.Bool(False),
            mi.Float(1.0),
        )

    def eval_pdf(
        self,
        material: mi.UInt32,
        wi: mi.Vector3f,
        wo: mi.Vector3f,
        wavelengths: mi.Spectrum,
        coherence: IncidentCoherence,
        frame: mi.Frame3f,
        wo_phase: mi.Vector3f,
    ) -> tuple[mi.Spectrum, mi.Float]:
        reflectance = self.params.spectrum(material, mat.REFLECTANCE_ID, wavelengths)
        return reflectance * (wo.z / math.pi), wo.z / math.pi
