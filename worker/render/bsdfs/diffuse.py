"""Lambertian reflector: f = ρ(λ)/π, cosine-weighted sampling (weight ρ, pdf cos θo/π)."""

from __future__ import annotations

import math

import mitsuba as mi

from worker.render import materials as mat
from worker.render.bsdfs.common import IncidentCoherence, Material, MaterialSample, ShadingPoint


class Diffuse(Material):
    kind = mat.MaterialKind.DIFFUSE
    hero_ratios = False
    spectra = (mat.REFLECTANCE_ID,)

    def _reflectance(self, point: ShadingPoint) -> mi.Spectrum:
        return point.spectra[mat.REFLECTANCE_ID]

    def sample(self, point: ShadingPoint, sample1: mi.Float, sample2: mi.Point2f) -> MaterialSample:
        direction = mi.warp.square_to_cosine_hemisphere(sample2)
        pdf = mi.warp.square_to_cosine_hemisphere_pdf(direction)
        return MaterialSample(
            direction, self._reflectance(point), mi.Spectrum(pdf), mi.Bool(False), mi.Float(1.0)
        )

    def eval_pdf(
        self, point: ShadingPoint, wo: mi.Vector3f, coherence: IncidentCoherence, wo_phase: mi.Vector3f
    ) -> tuple[mi.Spectrum, mi.Spectrum]:
        return self._reflectance(point) * (wo.z / math.pi), mi.Spectrum(wo.z / math.pi)
