"""The Dr.Jit ``ArrayOps`` namespace: runs the shared optics formulas of ``hgcore.optics`` inside Mitsuba's
``llvm_ad_*`` / ``cuda_ad_*`` symbolic loops. It lives with the worker because only the worker may import
Dr.Jit (``make lint``'s layer contracts); the service runs the same formulas on NumPy.
"""

from __future__ import annotations

import dataclasses

import drjit as dr

from hgcore.optics.array_ops import ArrayOps


def drjit_ops() -> ArrayOps:
    """The Dr.Jit namespace, for the optics formulas inside the integrator's kernels."""
    return dataclasses.replace(
        ArrayOps.of("drjit", dr, atan2=dr.atan2, where=dr.select), reciprocal_sqrt=dr.rsqrt
    )
