"""The noise-aware metrics on synthetic renders with known noise (no renderer involved).

A "render" of a known image μ (16×16 px, 8 bands) is μ plus Gaussian noise of known per-pixel variance v,
and its variance.exr holds v (scaled by (N−1)/N as the renderer writes it, undone by the loader). Under no
change every band statistic is N(0, 1), so the largest of 3 × 8 statistics exceeds z_crit = 5 with
probability < 24 × 5.7e-7 ≈ 1.4e-5 per comparison; with the fixed seeds below the outcome is deterministic.
"""

from __future__ import annotations

import numpy as np
import pytest

from hgcore.regression.images import RenderOutputs
from hgcore.regression.metrics import compare_renders
from hgcore.regression.models import Thresholds

SIZE_PX, BANDS, SPP = 16, 8, 8
CENTERS_NM = 380.0 + 50.0 * (np.arange(BANDS) + 0.5)


def truth(scale: float = 1.0) -> np.ndarray:
    y, x = np.mgrid[0:SIZE_PX, 0:SIZE_PX] / SIZE_PX
    spectrum = 0.5 + 0.4 * np.sin(CENTERS_NM / 60.0)
    return scale * (0.2 + x[..., None] * y[..., None]) * spectrum


def render(mean: np.ndarray, seed: int, noise_rel: float = 0.3, l1_um: float = 40.0) -> RenderOutputs:
    rng = np.random.default_rng(seed)
    variance = (noise_rel * mean) ** 2
    coherence_noise = 1.0 + 0.05 * rng.standard_normal((SIZE_PX, SIZE_PX))
    return RenderOutputs(
        band_centers_nm=CENTERS_NM,
        bands=mean + np.sqrt(variance) * rng.standard_normal(mean.shape),
        band_variance=variance,
        coherence={
            "l1_um": l1_um * coherence_noise,
            "l2_um": 0.5 * l1_um * coherence_noise,
            "anisotropy": np.full((SIZE_PX, SIZE_PX), 2.0),
            "weight": np.ones((SIZE_PX, SIZE_PX)),
        },
        spp=SPP,
    )


@pytest.mark.parametrize("seed", range(1, 6))
def test_noise_alone_passes(seed: int) -> None:
    comparison = compare_renders("scene", render(truth(), 0), render(truth(), seed), Thresholds())
    assert comparison.verdict == "pass", comparison.reasons
    # Calibration: every band statistic is a draw of N(0, 1) (|z| < 5 with overwhelming probability).
    assert comparison.metrics["z_max"] < 5.0
    assert comparison.metrics["delta_e00"]["p95"] > 0.0  # visibly noisy, and still a pass


def test_a_darker_image_fails_on_the_band_means() -> None:
    comparison = compare_renders("scene", render(truth(), 0), render(truth(0.8), 1), Thresholds())
    assert comparison.verdict == "fail"
    assert any(r.startswith("scene: rel_mean_change of band") for r in comparison.reasons)
    changes = [band["rel_mean_change"] for band in comparison.metrics["bands"]]
    # Each band mean averages 256 pixels of 30 % noise: standard error 0.3 / 16 ≈ 0.019 per band.
    np.testing.assert_allclose(changes, -0.2, atol=5 * 0.3 / SIZE_PX)


def test_a_change_below_the_threshold_passes_although_significant() -> None:
    # 2 % darker with 1 % noise: hugely significant (z ≈ 30) but under the 5 % effect-size threshold.
    baseline = render(truth(), 0, noise_rel=0.01)
    comparison = compare_renders("scene", baseline, render(truth(0.98), 1, noise_rel=0.01), Thresholds())
    assert comparison.metrics["z_max"] > 20.0
    assert comparison.verdict == "pass", comparison.reasons


def test_coherence_drift_fails_with_the_sign_test() -> None:
    comparison = compare_renders("scene", render(truth(), 0), render(truth(), 1, l1_um=30.0), Thresholds())
    assert any(r.startswith("scene: coherence_drift of l1_um is -0.2") for r in comparison.reasons)
    drift = comparison.metrics["coherence"]["l1_um"]
    # Per pixel 0.75 (1 + ε₁)/(1 + ε₀) − 1 with 5 % noise each: spread ≈ 0.75 · 0.05 · √2 ≈ 0.053, so the
    # median of 256 pixels has standard error ≈ 1.25 · 0.053 / 16 ≈ 0.0042; 5σ tolerance.
    assert drift["median_rel_change"] == pytest.approx(-0.25, abs=0.021)
    # Every one of the 256 covered pixels decreased: the sign test's z is -√256 = -16 exactly.
    assert drift["z_sign"] == pytest.approx(-16.0)
    assert comparison.metrics["coherence"]["anisotropy"]["median_rel_change"] == 0.0


def test_a_colour_shift_fails_on_delta_e00() -> None:
    shifted = truth() * np.linspace(1.6, 0.4, BANDS)  # blue up, red down: a strong hue change
    comparison = compare_renders("scene", render(truth(), 0, 0.05), render(shifted, 1, 0.05), Thresholds())
    assert any(r.startswith("scene: delta_e00_p95 is") for r in comparison.reasons), comparison.reasons
    assert comparison.metrics["delta_e00"]["p95_excess"] > 2.0


def test_different_layouts_fail_with_a_reason() -> None:
    small = render(truth()[:8, :8], 1)
    comparison = compare_renders("scene", render(truth(), 0), small, Thresholds())
    assert comparison.verdict == "fail" and "image layout changed" in comparison.reasons[0]


def test_delta_e00_is_at_the_exposure_that_maps_the_baseline_p99_to_white() -> None:
    """The stored ΔE₀₀ is CIEDE2000 with the white at the baseline's 99th-percentile Y (independently:
    scaling the white instead of the images), and the run stores that exposure."""
    from hgcore.colour import D65_WHITE_XYZ, bands_to_xyz, ciede2000, xyz_to_lab, y_bar_integral_nm

    baseline, current = render(truth(), 0, 0.05), render(truth() * np.linspace(1.3, 0.7, BANDS), 1, 0.05)
    comparison = compare_renders("scene", baseline, current, Thresholds())
    xyz_a, xyz_c = bands_to_xyz(baseline.bands, CENTERS_NM), bands_to_xyz(current.bands, CENTERS_NM)
    white_y = float(np.percentile(xyz_a[..., 1], 99.0))
    expected = ciede2000(
        xyz_to_lab(xyz_a, D65_WHITE_XYZ * white_y), xyz_to_lab(xyz_c, D65_WHITE_XYZ * white_y)
    )
    # The EV is on the scale of linear sRGB (Y / ∫ȳ dλ), as the viewer's exposure.
    assert comparison.metrics["exposure_ev"] == pytest.approx(
        -np.log2(white_y / y_bar_integral_nm()), rel=1e-12
    )
    assert comparison.metrics["delta_e00"]["p95"] == pytest.approx(np.percentile(expected, 95.0), rel=1e-9)
    assert comparison.metrics["delta_e00"]["exposure_ev"] == comparison.metrics["exposure_ev"]


def test_flip_passes_noise_and_fails_a_colour_shift() -> None:
    noise = compare_renders("scene", render(truth(), 0, 0.05), render(truth(), 1, 0.05), Thresholds())
    assert noise.verdict == "pass", noise.reasons
    # Identical noise statistics: the ꟻLIP of a noise pair is about its bootstrap noise level.
    assert 0.0 < noise.metrics["flip"]["mean"] < 2 * noise.metrics["flip"]["mean_noise"]
    shifted = truth() * np.linspace(1.6, 0.4, BANDS)
    changed = compare_renders("scene", render(truth(), 0, 0.05), render(shifted, 1, 0.05), Thresholds())
    assert any(r.startswith("scene: flip_mean is") for r in changed.reasons), changed.reasons
    assert changed.metrics["flip"]["mean_excess"] > Thresholds().max_flip_mean
    # ꟻLIP errors lie in [0, 1].
    assert 0.0 <= changed.metrics["flip"]["mean"] <= changed.metrics["flip"]["max"] <= 1.0
