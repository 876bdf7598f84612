"""The renderer's film kernel carries the absorbing film's complex index n_f + iκ_f end to end.

``film_terms`` (what sampling, next-event estimation and ``rlt`` all evaluate) of a compiled one-material
scene against the NumPy float64 closed form with the complex index; float32 kernels: 2e-5 allowed (a few
float32 ulps of terms that are O(1), amplified by the 1/(1 − |b|²) of the beam series, |b| ≤ 0.9 here).
"""

from __future__ import annotations

import numpy as np
import pytest

from hgcore.optics.array_ops import NUMPY
from hgcore.optics.complex_pair import ComplexPair
from hgcore.optics.ior import spectral_ior
from hgcore.optics.thin_film import film_reflectance_terms
from tests.render.kernel_harness import KernelProbe

WAVELENGTHS_NM = np.array([430.0, 510.0, 580.0, 660.0])
COS_I = np.cos(np.radians(np.array([0.0, 20.0, 40.0, 60.0, 75.0])))
FLOAT32_TOLERANCE = 2e-5


def coated_silver(extinction: float) -> dict:
    return {
        "type": "thin_film",
        "film_thickness_um": 0.12,
        "film_ior": 2.7,
        "film_extinction": extinction,
        "substrate": {"conductor": "Ag"},
        "beams": 4,
    }


def kernel_terms(extinction: float) -> tuple[np.ndarray, bool]:
    """[R_incoherent, X_1 …] (slot, angle, wavelength) from the kernels, and whether they run complex."""
    probe = KernelProbe(coated_silver(extinction))
    mi = probe.mi
    count = COS_I.size
    spectrum = mi.Spectrum(0.0)
    for j in range(len(spectrum)):
        spectrum[j] = mi.Float(np.full(count, WAVELENGTHS_NM[j], dtype=np.float32))
    material = mi.UInt32(np.zeros(count, dtype=np.uint32))
    terms = probe.kernels.film_terms(material, mi.Float(COS_I.astype(np.float32)), spectrum)
    values = np.array([[np.asarray(term[j], dtype=float) for j in range(len(term))] for term in terms])
    return values.transpose(0, 2, 1), probe.kernels.params.film_absorbing


def reference_terms(extinction: float) -> np.ndarray:
    rows = []
    for wavelength_nm in WAVELENGTHS_NM:
        n, kappa = (float(np.asarray(v).ravel()[0]) for v in spectral_ior("Ag", wavelength_nm))
        like = np.ones_like(COS_I)
        rows.append(
            film_reflectance_terms(
                COS_I,
                wavelength_nm * 1e-9,
                0.12e-6,
                ComplexPair(2.7 * like, extinction * like),
                ComplexPair(n * like, kappa * like),
                1.0,
                4,
                NUMPY,
            )
        )
    return np.array(rows).transpose(1, 2, 0)  # (slot, angle, wavelength)


@pytest.mark.parametrize("extinction", [0.0, 0.4, 2.0])
def test_kernel_film_terms_follow_the_complex_index(extinction: float) -> None:
    values, absorbing = kernel_terms(extinction)
    assert absorbing == (extinction > 0.0)  # κ = 0 keeps the real-index trace (bitwise as before)
    expected = reference_terms(extinction)
    np.testing.assert_allclose(values, expected, rtol=0, atol=FLOAT32_TOLERANCE)
    if extinction > 0.0:  # the extinction matters: the clear film's terms are far off
        assert np.abs(reference_terms(0.0) - expected).max() > 100 * FLOAT32_TOLERANCE
