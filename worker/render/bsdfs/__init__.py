"""Kernel-side evaluation and sampling of hgrender materials, for the ``hg_path`` integrator.

One module per material kind, each a ``common.Material`` (the interface: ``sample``, ``eval_pdf`` and the
lanes they apply to): ``diffuse``, ``mirror``, ``dielectric`` (smooth), ``rough_conductor`` (Eq. 15),
``rough_dielectric`` (Eq. 15, both sides), ``thin_film`` (Eq. 18), ``grating`` (Eq. 20); ``lobes`` holds
the "specular part with probability p, else the lobe" skeleton they share. ``dispatch``'s
``MaterialKernels`` selects the branch of each lane. The physics lives in ``hgcore.optics``; these modules
gather parameters, choose lobes and combine the four wavelengths (conventions: ``common``).
"""

from worker.render.bsdfs.common import (
    IncidentCoherence,
    MaterialParams,
    MaterialSample,
    VertexSpectra,
    VisibilityModel,
)
from worker.render.bsdfs.dispatch import MaterialKernels

__all__ = [
    "IncidentCoherence",
    "MaterialKernels",
    "MaterialParams",
    "MaterialSample",
    "VertexSpectra",
    "VisibilityModel",
]
