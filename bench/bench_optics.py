"""Throughput of the optics interaction formulas inside Dr.Jit LLVM kernels, on one CPU thread.

Measured (issue 2, "Performance"; targets ≥ 1e7/s for the 0th mode and ≥ 1e6/s for 16 modes):

* ``thin_film_0th_mode``: per sample, the incident degree of coherence at the film's transverse separation
  from a 2×2 Σ⊥ (``coherence.degree_of_coherence`` with the single 0th-mode coefficient; V_d = V_1^{d²}),
  the Fresnel amplitudes of both interfaces and the partially-coherent sum of Eq. (18) generalised to
  ``FILM_BEAMS`` beams (``thin_film.thin_film_reflectance``), on a silver substrate. (Two beams, Eq. (18)
  literally, over-estimate R on a metal, where |r_12| ≈ 1 makes the higher beams matter.)
* ``thin_film_16_modes``: the same with the 16-mode uniform-disk expansion evaluated at each of the
  FILM_BEAMS − 1 separations d·ξ.
* ``grating_brdf``: the 0th-mode CD grating BRDF (all propagating orders, ``grating.grating_eval``).

Inputs (``count`` random samples) are made on the host and evaluated on the device before timing; each timed
run traces the formula, compiles or reuses the kernel and copies the result back to the host
(``np.array``), so lazy evaluation cannot hide work. The first run (which includes JIT compilation) is
reported separately from the best of ``repeats`` warm runs. Results go to stdout and
``bench/results/optics.json`` (written atomically).
"""

from __future__ import annotations

import json
import math
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from bench.machine import cpu_model, cpu_reference_s, write_results
from hgcore.optics.coherence import degree_of_coherence
from hgcore.optics.complex_pair import ComplexPair
from hgcore.optics.grating import CD_GRATING, grating_eval
from hgcore.optics.sources import source_coefficients
from hgcore.optics.thin_film import gaussian_visibilities, thin_film_reflectance
from worker.mitsuba_setup import configure_mitsuba

SAMPLE_COUNT = 10_000_000
WARM_REPEATS = 3
TARGET_0TH_PER_S = 1e7
TARGET_16_PER_S = 1e6
FILM_BEAMS = 4


def _time_formula(formula: Callable[[], Any], count: int, repeats: int) -> dict[str, float]:
    """First (compile) run and best warm run of ``formula``, each ending in a host transfer."""
    timings = []
    for _ in range(1 + repeats):
        start = time.perf_counter()
        result = np.array(formula())
        timings.append(time.perf_counter() - start)
        if not np.all(np.isfinite(result)):
            raise RuntimeError("benchmark formula produced non-finite values")
    best = min(timings[1:])
    return {
        "first_run_s": timings[0],
        "best_warm_s": best,
        "evaluations_per_s": count / best,
    }


def main(count: int = SAMPLE_COUNT, repeats: int = WARM_REPEATS) -> dict[str, Any]:
    """Run the three measurements and write ``bench/results/optics.json``."""
    configure_mitsuba("llvm_ad_spectral")  # sets DRJIT_LIBLLVM_PATH to libLLVM 19 before Dr.Jit starts
    import drjit as dr
    from drjit.llvm import Float

    from worker.render.drjit_ops import drjit_ops

    dr.set_thread_count(1)  # before the first kernel: one core, as the issue's targets assume
    ops = drjit_ops()
    rng = np.random.default_rng(2021)

    def device(values: np.ndarray) -> Any:
        array = Float(values.astype(np.float32))
        dr.eval(array)
        return array

    cos_theta_i = device(rng.uniform(0.05, 1.0, count))
    wavelength_m = device(rng.uniform(380e-9, 780e-9, count))
    thickness_m = device(rng.uniform(0.2e-6, 2.0e-6, count))
    separation_x_m = device(rng.uniform(-2e-6, 2e-6, count))
    separation_y_m = device(rng.uniform(-2e-6, 2e-6, count))
    # A 1 cm × 3 cm source at 0.6 m, rotated: a generic anisotropic Σ⊥ (m²).
    sigma_m2 = (Float(2.0e-5), Float(-0.6e-5), Float(6.0e-5))
    distance_m = Float(0.6)
    silver = ComplexPair(Float(0.13), Float(3.4))  # Palik, ≈ 600 nm
    film_ior = Float(1.5)

    def visibility_at(separation: int, coefficients: dict[tuple[int, int], float]) -> Any:
        xi = (separation * separation_x_m, separation * separation_y_m)
        return degree_of_coherence(xi, sigma_m2, distance_m, wavelength_m, coefficients, ops)

    def thin_film(coefficients: dict[tuple[int, int], float]) -> Callable[[], Any]:
        def formula() -> Any:
            if len(coefficients) == 1:  # Gaussian degree of coherence: V_d = V_1^{d²}
                visibilities = gaussian_visibilities(visibility_at(1, coefficients), FILM_BEAMS - 1, ops)
            else:
                visibilities = [visibility_at(d, coefficients) for d in range(1, FILM_BEAMS)]
            return thin_film_reflectance(
                cos_theta_i, wavelength_m, thickness_m, film_ior, silver, 1.0, visibilities, ops
            )

        return formula

    sin_i = dr.sqrt(1.0 - cos_theta_i * cos_theta_i)
    azimuth_i = device(rng.uniform(0.0, 2.0 * math.pi, count))
    wi = (sin_i * dr.cos(azimuth_i), sin_i * dr.sin(azimuth_i), cos_theta_i)
    cos_theta_o = device(rng.uniform(0.05, 1.0, count))
    azimuth_o = device(rng.uniform(0.0, 2.0 * math.pi, count))
    sin_o = dr.sqrt(1.0 - cos_theta_o * cos_theta_o)
    wo = (sin_o * dr.cos(azimuth_o), sin_o * dr.sin(azimuth_o), cos_theta_o)
    dr.eval(wi, wo)
    angular_cov = (Float(1e-5), Float(0.0), Float(1e-5))

    def grating() -> Any:
        return grating_eval(CD_GRATING, wi, wo, wavelength_m, 0.9, angular_cov, ops)

    zeroth = _time_formula(thin_film(source_coefficients("disk", 1)), count, repeats)
    sixteen = _time_formula(thin_film(source_coefficients("disk", 16)), count, repeats)
    grating_result = _time_formula(grating, count, repeats)
    results: dict[str, Any] = {
        "backend": "drjit-llvm",
        "drjit_version": dr.__version__,
        "threads": 1,
        "cpu": cpu_model(),
        "cpu_reference_s": cpu_reference_s(),
        "samples": count,
        "thin_film_0th_mode": {**zeroth, "beams": FILM_BEAMS, "target_per_s": TARGET_0TH_PER_S},
        "thin_film_16_modes": {**sixteen, "beams": FILM_BEAMS, "target_per_s": TARGET_16_PER_S},
        "grating_brdf": {**grating_result, "orders": len(CD_GRATING.orders())},
    }
    results["targets_met"] = (
        zeroth["evaluations_per_s"] >= TARGET_0TH_PER_S and sixteen["evaluations_per_s"] >= TARGET_16_PER_S
    )
    write_results("optics", results)
    return results


if __name__ == "__main__":
    json.dump(main(), sys.stdout, indent=2)
    sys.stdout.write("\n")
