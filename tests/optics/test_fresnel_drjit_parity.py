"""The interaction kernels give the same values inside Dr.Jit (LLVM, float32) as on NumPy (float64).

Every formula in fresnel / rough_surface / thin_film / grating is written once against ``ops``; this runs
each on the same inputs (rounded to float32 first) through both namespaces. Float32 rounding (ε ≈ 6e-8)
accumulated over the ≲ 10² operations of a formula, amplified by at most ~10 in the cancellations of the
Fresnel denominators and Gaussian exponents (|exponent| ≲ 20 → relative error ≲ 20·ε_rel of the exponent),
stays below 1e-4 relative to the largest value of each output; that is the tolerance.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from hgcore.optics.array_ops import NUMPY
from hgcore.optics.complex_pair import ComplexPair
from hgcore.optics.fresnel import fresnel_dielectric, fresnel_reflectance
from hgcore.optics.grating import CD_GRATING, grating_eval, grating_pdf, grating_sample
from hgcore.optics.rough_surface import (
    RoughSurface,
    rough_reflection_eval,
    rough_reflection_pdf,
    rough_reflection_sample,
)
from hgcore.optics.thin_film import gaussian_visibilities, thin_film_reflectance

TOLERANCE = 1e-4
COUNT = 4096


@pytest.fixture(scope="module")
def drjit_env() -> tuple[Any, Any, Any]:
    from worker.mitsuba_setup import configure_mitsuba

    configure_mitsuba("llvm_ad_spectral")
    import drjit as dr
    from drjit.llvm import Float

    from worker.render.drjit_ops import drjit_ops

    return dr, Float, drjit_ops()


def _inputs() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(99)
    cos_i = rng.uniform(0.05, 1.0, COUNT)
    phi_i = rng.uniform(0, 2 * math.pi, COUNT)
    cos_o = rng.uniform(0.05, 1.0, COUNT)
    phi_o = rng.uniform(0, 2 * math.pi, COUNT)
    values = {
        "cos_i": cos_i,
        "wi_x": np.sqrt(1 - cos_i**2) * np.cos(phi_i),
        "wi_y": np.sqrt(1 - cos_i**2) * np.sin(phi_i),
        "wo_x": np.sqrt(1 - cos_o**2) * np.cos(phi_o),
        "wo_y": np.sqrt(1 - cos_o**2) * np.sin(phi_o),
        "cos_o": cos_o,
        "wavelength_m": rng.uniform(380e-9, 780e-9, COUNT),
        "thickness_m": rng.uniform(0.1e-6, 1.5e-6, COUNT),
        "visibility": rng.uniform(0.0, 1.0, COUNT),
        "u1": rng.uniform(0.0, 1.0, COUNT),
        "u2": rng.uniform(0.0, 1.0, COUNT),
        "u3": rng.uniform(0.0, 1.0, COUNT),
    }
    return {key: value.astype(np.float32).astype(np.float64) for key, value in values.items()}


def _compare(name: str, numpy_value: Any, drjit_value: Any) -> None:
    reference = np.asarray(numpy_value, dtype=float)
    result = np.asarray(drjit_value, dtype=float)
    scale = max(float(np.max(np.abs(reference))), 1e-30)
    np.testing.assert_allclose(result, reference, atol=TOLERANCE * scale, rtol=0.0, err_msg=name)


def _kernels(inputs: dict[str, Any], ops: Any) -> dict[str, Any]:
    wi = (inputs["wi_x"], inputs["wi_y"], inputs["cos_i"])
    wo = (inputs["wo_x"], inputs["wo_y"], inputs["cos_o"])
    gold = ComplexPair(0.27 + 0.0 * inputs["cos_i"], 2.9 + 0.0 * inputs["cos_i"])
    surface = RoughSurface(rms_height_m=30e-9, correlation_length_m=0.8e-6, psd_model="abc", abc_exponent=2.2)
    cov = (2e-4 + 0.0 * inputs["cos_i"], 0.5e-4 + 0.0 * inputs["cos_i"], 1e-4 + 0.0 * inputs["cos_i"])
    sampled_wo, sampled_pdf, _ = rough_reflection_sample(
        surface, wi, inputs["wavelength_m"], inputs["u1"], inputs["u2"], ops
    )
    grating_wo, grating_sample_pdf, _, grating_weight = grating_sample(
        CD_GRATING, wi, inputs["wavelength_m"], cov, inputs["u3"], inputs["u1"], inputs["u2"], ops
    )
    return {
        "fresnel_conductor": fresnel_reflectance(inputs["cos_i"], gold, ops),
        "fresnel_dielectric": fresnel_dielectric(inputs["cos_i"], 1.0 / 1.5 + 0.0 * inputs["cos_i"], ops)[0],
        "thin_film": thin_film_reflectance(
            inputs["cos_i"],
            inputs["wavelength_m"],
            inputs["thickness_m"],
            1.45 + 0.0 * inputs["cos_i"],
            gold,
            1.0,
            gaussian_visibilities(inputs["visibility"], 5, ops),
            ops,
        ),
        "rough_eval": rough_reflection_eval(surface, wi, wo, inputs["wavelength_m"], 0.9, ops),
        "rough_pdf": rough_reflection_pdf(surface, wi, wo, inputs["wavelength_m"], ops),
        "rough_sample_x": sampled_wo[0],
        "rough_sample_pdf": sampled_pdf,
        "grating_eval": grating_eval(CD_GRATING, wi, wo, inputs["wavelength_m"], 0.9, cov, ops),
        "grating_pdf": grating_pdf(CD_GRATING, wi, wo, inputs["wavelength_m"], cov, ops),
        "grating_sample_x": grating_wo[0],
        "grating_sample_pdf": grating_sample_pdf,
        "grating_weight": grating_weight,
    }


def test_kernels_agree_between_numpy_and_drjit(drjit_env: tuple[Any, Any, Any]) -> None:
    dr, Float, ops = drjit_env
    inputs = _inputs()
    reference = _kernels(inputs, NUMPY)
    device_inputs = {key: Float(value.astype(np.float32)) for key, value in inputs.items()}
    result = _kernels(device_inputs, ops)
    for name, value in reference.items():
        evaluated = result[name]
        dr.eval(evaluated)
        _compare(name, value, np.array(evaluated))
