"""Coherence calculator: the coherence a source gives a receiver at a distance (issue 2, item 7).

Backs ``hgrender coherence`` and the service's ``POST /v1/coherence``; it uses NumPy/SciPy only (never Mitsuba
or Dr.Jit). For a source kind and size seen along ``direction`` from ``distance_m`` away it returns Σ⊥ (m²),
Θ = Σ⊥⁻¹ (1/m², Lemma 4.4 with its sign), M = (k/r)²Σ⊥ (1/m²), the BRIEF's diagnostics ℓ₁, ℓ₂ (µm),
anisotropy, angle (rad), area (µm²) at ``wavelength_nm``, and the HG coefficients of Eq. (14) in the
whitened basis of ``hgcore.optics.sources`` (normalised so that μ(0) = 1).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from hgcore.errors import InputError
from hgcore.optics.coherence import (
    coherence_diagnostics,
    require_positive_definite,
    shape_matrix_from_covariance,
)
from hgcore.optics.sources import (
    MAX_MODES,
    SOURCE_KINDS,
    positive_size,
    source_coefficients,
    transverse_covariance,
)

MIN_WAVELENGTH_NM = 200.0
MAX_WAVELENGTH_NM = 2500.0
NANOMETRES_TO_METRES = 1e-9


def _wavelength_m(wavelength_nm: float) -> float:
    value = float(wavelength_nm)
    if not math.isfinite(value) or not MIN_WAVELENGTH_NM <= value <= MAX_WAVELENGTH_NM:
        raise InputError(
            f"wavelength_nm: must be within {MIN_WAVELENGTH_NM:g}-{MAX_WAVELENGTH_NM:g} nm, "
            f"got {wavelength_nm}"
        )
    return value * NANOMETRES_TO_METRES


def _mode_count(modes: int) -> int:
    if isinstance(modes, bool) or not isinstance(modes, int) or not 1 <= modes <= MAX_MODES:
        raise InputError(f"modes: must be an integer in 1..{MAX_MODES}, got {modes!r}")
    return modes


def _matrix(values: Any) -> list[list[float]]:
    return [[float(values[0][0]), float(values[0][1])], [float(values[1][0]), float(values[1][1])]]


def coherence_at(
    source: str,
    *,
    radius_m: float | None = None,
    length_m: float | None = None,
    width_m: float | None = None,
    height_m: float | None = None,
    sigma_m: float | None = None,
    distance_m: float,
    wavelength_nm: float = 550.0,
    axis: Sequence[float] = (1.0, 0.0, 0.0),
    direction: Sequence[float] = (0.0, 0.0, 1.0),
    modes: int = 1,
) -> dict[str, Any]:
    """Coherence of the light from ``source`` after ``distance_m`` metres (one JSON-ready dict).

    Sizes in metres (sphere/disk/cylinder: radius_m; cylinder: length_m; rect: width_m, height_m;
    gaussian: sigma_m). ``axis``: cylinder axis, or the in-plane axis of a disk/rect about which it faces
    the receiver. ``direction``: propagation direction from source to receiver. Raises ValueError naming
    the offending parameter for any invalid input.
    """
    if source not in SOURCE_KINDS:
        raise InputError(f"source: must be one of {', '.join(SOURCE_KINDS)}, got {source!r}")
    wavelength_m = _wavelength_m(wavelength_nm)
    distance = positive_size(distance_m, "distance_m")
    mode_count = _mode_count(modes)
    covariance = transverse_covariance(
        source,
        direction=direction,
        axis=axis,
        radius_m=radius_m,
        length_m=length_m,
        width_m=width_m,
        height_m=height_m,
        sigma_m=sigma_m,
    )
    # A flat source seen (nearly) edge-on has a singular Σ⊥: an infinite coherence length is not a beam.
    sigma = require_positive_definite(covariance.sigma_m2, "direction (source seen edge-on: sigma_m2)")
    theta = shape_matrix_from_covariance(sigma)
    diagnostics = coherence_diagnostics(sigma, distance, wavelength_m)
    coefficients = source_coefficients(source, mode_count)
    return {
        "source": source,
        "wavelength_nm": float(wavelength_nm),
        "r_m": distance,
        "l1_um": diagnostics.l1_um,
        "l2_um": diagnostics.l2_um,
        "anisotropy": diagnostics.anisotropy,
        "angle": diagnostics.angle,
        "area_um2": diagnostics.area_um2,
        "theta": _matrix(theta),
        "sigma_m2": _matrix(sigma),
        "M": _matrix(diagnostics.M_per_m2),
        "coefficients": [{"n": n, "m": m, "value": value} for (n, m), value in coefficients.items()],
        "frame": {
            "x_axis": [float(c) for c in covariance.x_axis],
            "y_axis": [float(c) for c in covariance.y_axis],
            "direction": [float(c) for c in covariance.direction],
        },
    }
