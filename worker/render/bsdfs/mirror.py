"""Perfect mirror (Dirac): reflects with the Fresnel reflectance of its conductor (Ag, Au, Cu, Al) or 1."""

from __future__ import annotations

import mitsuba as mi

from worker.render import materials as mat
from worker.render.bsdfs.common import Material, MaterialSample


class Mirror(Material):
    kind = mat.MaterialKind.MIRROR

    def sample(
        self,
        material: mi.UInt32,
        wi: mi.Vector3f,
        wavelengths: mi.Spectrum,
        sample1: mi.Float,
        sample2: mi.Point2f,
        collapsed: mi.Bool,
    ) -> MaterialSample:
        return MaterialSample(
            mi.reflect(wi),
            self.params.interface_reflectance(material, wi.z, wavelengths),
            mi.Float(1.0),
            mi.Bool(True),
            mi.Float(1.0),
        )
