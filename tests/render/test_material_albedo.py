"""Directional albedo of the rough materials as the path tracer's kernels sample them.

For a view direction ω the mean sample weight is ∫ f |cos θ_o| dω_o plus the Dirac parts: Harvey–Shack
renormalised over the propagating frequencies (``rough_surface``) gives exactly F(θ) for a rough conductor
— never more than its Fresnel reflectance — and R + T/η² for a rough dielectric (radiance divided by η² =
(n_light/n_camera)² on transmission), η the relative index. The four wavelengths of a path are a rotation
of one stratified set, and the kernels' hero-wavelength MIS is unbiased over that rotation, so each
expectation is averaged over the four rotations of the wavelength set. Monte Carlo error: 4 × 100 000
samples per angle, per-sample weights ≤ ~5, so SE ≤ 3e-3; the tolerance is 5 SE, computed from the samples.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from hgcore.optics.array_ops import NUMPY
from hgcore.optics.complex_pair import ComplexPair
from hgcore.optics.fresnel import fresnel_dielectric, fresnel_reflectance
from hgcore.optics.ior import spectral_ior
from tests.render.kernel_harness import KernelProbe, direction

WAVELENGTHS_NM = np.array([450.0, 550.0, 650.0, 750.0])
SAMPLES = 100_000


def rotation_averaged_albedo(probe: KernelProbe, wi: np.ndarray, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    means, variances = [], []
    for rotation in range(len(WAVELENGTHS_NM)):
        wavelengths = np.roll(WAVELENGTHS_NM, -rotation)
        weight = probe.sample(wi, wavelengths, rng.random((len(wi), 3)))["weight"]
        means.append(np.roll(weight.mean(axis=0), rotation))
        variances.append(np.roll(weight.var(axis=0), rotation) / len(wi))
    rotations = len(WAVELENGTHS_NM)
    return np.mean(means, axis=0), np.sqrt(np.sum(variances, axis=0)) / rotations


@pytest.mark.slow  # ≈ 40 s each: the kernels' JIT compilation dominates
def test_rough_conductor_albedo_is_its_fresnel_reflectance() -> None:
    probe = KernelProbe(
        {"type": "rough_conductor", "conductor": "Au", "roughness_rms_um": 0.2, "correlation_length_um": 1.0}
    )
    n, kappa = spectral_ior("Au", WAVELENGTHS_NM)
    for theta_deg in (0.0, 45.0, 70.0, 82.0):
        albedo, error = rotation_averaged_albedo(probe, direction(theta_deg, SAMPLES), seed=int(theta_deg))
        cos_theta = np.full(4, math.cos(math.radians(theta_deg)))
        fresnel = fresnel_reflectance(cos_theta, ComplexPair(n, kappa), NUMPY)
        # 4e-3 relative: the documented error of the propagating fraction's angular rule (θ ≤ 82°).
        assert np.all(np.abs(albedo - fresnel) <= 5 * error + 4e-3 * fresnel), (theta_deg, albedo, fresnel)
        assert np.all(albedo <= fresnel * (1 + 4e-3) + 5 * error)


@pytest.mark.slow
@pytest.mark.parametrize(("rms_um", "correlation_um"), [(0.19, 1.0), (0.1, 2.0), (0.2, 20.0)])
def test_rough_dielectric_albedo_conserves_energy(rms_um: float, correlation_um: float) -> None:
    probe = KernelProbe(
        {
            "type": "rough_dielectric",
            "ior": 1.5,
            "roughness_rms_um": rms_um,
            "correlation_length_um": correlation_um,
        }
    )
    for theta_deg in (0.0, 40.0, 75.0):
        for inside in (False, True):
            wi = direction(theta_deg, SAMPLES, lower=inside)
            albedo, error = rotation_averaged_albedo(probe, wi, seed=int(theta_deg) + 100 * inside)
            eta = 1 / 1.5 if inside else 1.5
            reflectance, cos_t = fresnel_dielectric(np.array(math.cos(math.radians(theta_deg))), eta, NUMPY)
            transmittance = 0.0 if float(cos_t) == 0.0 else 1.0 - float(reflectance)
            expected = float(reflectance) + transmittance / eta**2
            assert np.all(np.abs(albedo - expected) <= 5 * error + 4e-3 * expected), (
                theta_deg,
                inside,
                albedo,
            )
