"""Perfect mirror (Dirac): reflects with the Fresnel reflectance of its conductor (Ag, Au, Cu, Al) or 1, times
its tint (``materials.TINT_ID``) where the scene has tints."""

from __future__ import annotations

import mitsuba as mi

from worker.render import materials as mat
from worker.render.bsdfs.common import Material, MaterialSample, ShadingPoint


class Mirror(Material):
    kind = mat.MaterialKind.MIRROR
    hero_ratios = False
    spectra = (mat.ETA_ID, mat.KAPPA_ID, mat.TINT_ID)

    def sample(self, point: ShadingPoint, sample1: mi.Float, sample2: mi.Point2f) -> MaterialSample:
        wi = point.wi
        reflectance = self.params.tint(self.params.interface_reflectance(point.spectra, wi.z), point.spectra)
        return MaterialSample(mi.reflect(wi), reflectance, mi.Spectrum(1.0), mi.Bool(True), mi.Float(1.0))
