"""Importance sampling of wavelengths (``film.wavelength_sampling``, worker/render/wavelength_sampling.py).

* The Dr.Jit sampler draws what its density says: the quantile table holds each band's tabulated mass,
  Pearson χ² of the drawn wavelengths over half cells against N·∫p, the lanes' ratios (1/Λ)/p(λ) against
  the host density at the drawn λ, and each lane's band against the band λ lies in.
* Unbiased: the per-band image means of a diffuse plane under an F11 lamp agree between ``importance`` and
  ``uniform`` within 4 combined standard errors (each from the render's own per-pixel variance), and the
  Cornell box under F11 agrees with Mitsuba's ``path`` (tests/render/test_reference_path.py's criterion).
* Lower colour noise: the chroma variance (CIELAB a*, b* about their image means, white = the patch's mean)
  of a white plane under F11 at 16 spp falls by at least 2× — asserted on the ratio's 3σ lower bound, σ from
  the spread of the per-pixel squared deviations (the variance estimates' own sampling error).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from hgcore.artifacts.images import images_from_sums
from hgcore.artifacts.layout import BandLayout
from hgcore.colour import linear_srgb_to_lab
from hgcore.optics.spectra import cie_illuminant
from hgcore.settings import SceneLimits
from schemas import build
from schemas.validation import validate_scene
from tests.integrator.scenes import plane_under_source
from tests.support.chi2 import discrete_chi2, sidak_level
from tests.support.scenes import example
from worker.mitsuba_setup import configured_mitsuba
from worker.render.renderer import Renderer
from worker.render.scene_compiler import SceneCompiler
from worker.render.wavelength_sampling import (
    BAND_MASS_FLOOR,
    WITHIN_BAND_FLOOR,
    WavelengthSampler,
    importance_density,
    knot_pdf_nm,
    line_spikiness,
    quantile_knots,
    sampling_mode,
)

F11_SPHERE = build.sphere([0.0, 0.3, 1.0], 0.2, spectrum={"type": "cie_f", "name": "F11"}, power_w=50.0)


def f11_density(bands: BandLayout):
    return importance_density(bands, lambda wavelengths: cie_illuminant("f11", wavelengths))


def test_density_keeps_its_floors() -> None:
    bands = BandLayout(380.0, 780.0, 16)
    density = f11_density(bands)
    cells = density.probabilities.reshape(bands.band_count, density.cells_per_band)
    masses = cells.sum(axis=1)
    assert math.isclose(density.probabilities.sum(), 1.0, rel_tol=1e-12)
    assert np.all(masses >= BAND_MASS_FLOOR / bands.band_count * (1 - 1e-12))
    assert np.all(cells >= WITHIN_BAND_FLOOR * masses[:, None] / density.cells_per_band * (1 - 1e-12))
    # F11's 545 nm line: the 540-550 nm cells hold most of the 530-555 nm band's mass.
    band = int((545.0 - 380.0) // bands.width_nm)
    line = (np.arange(density.cells_per_band) + 0.5) * density.cell_nm + bands.edges_nm[band]
    in_line = (line >= 540.0) & (line <= 550.0)
    assert cells[band, in_line].sum() > 0.6 * masses[band]


@pytest.mark.parametrize(
    ("spectrum", "mode"),
    [
        ({"type": "cie_f", "name": "F11"}, "importance"),
        ({"type": "cie_f", "name": "F7"}, "importance"),
        ({"type": "cie_f", "name": "F2"}, "importance"),
        ({"type": "d65"}, "uniform"),
        ({"type": "blackbody", "temperature_k": 3000.0}, "uniform"),
        ({"type": "constant", "value": 1.0}, "uniform"),
    ],
)
def test_auto_samples_line_spectra_by_importance(spectrum: dict, mode: str) -> None:
    source = build.sphere([0.0, 0.3, 1.0], 0.2, spectrum=spectrum, power_w=50.0)
    scene = validate_scene(plane_under_source(source))
    assert scene.film.wavelength_sampling == "auto"
    assert sampling_mode(scene) == mode


def test_line_spikiness_of_flat_and_single_line_spectra() -> None:
    assert line_spikiness(np.ones_like, 380.0, 780.0) == pytest.approx(1.0, abs=1e-12)

    # A box line 2 nm wide inside one 20 nm window: that window holds all power, ⟨Φ²⟩/⟨Φ⟩² = 20/2.
    def line(wavelengths: np.ndarray) -> np.ndarray:
        return ((wavelengths >= 549.0) & (wavelengths < 551.0)).astype(float)

    assert line_spikiness(line, 380.0, 780.0) == pytest.approx(10.0, rel=0.01)


def _draw(bands: BandLayout, density, count: int, seed: int):
    mi = configured_mitsuba()
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(seed, count)
    hero_set = WavelengthSampler(mi, bands, density).sample(sampler.next_1d())
    wavelengths = np.array(hero_set.wavelengths, dtype=np.float64)  # (4, N)
    ratios = np.stack([np.array(r, dtype=np.float64) for r in hero_set.ratios])
    band_of_lane = np.stack([np.array(b) for b in hero_set.band_of_lane])
    return wavelengths, ratios, band_of_lane


def test_sampler_matches_its_density() -> None:
    bands = BandLayout(380.0, 780.0, 16)
    density = f11_density(bands)
    knots = quantile_knots(density)
    # The quantile table's density follows the tabulated one: the same mass in every band, to the float32
    # rounding of its knots (ulp 3e-5 nm at 500 nm, against intervals down to ~0.05 nm on F11's lines).
    band_cdf = np.interp(bands.edges_nm, knots, np.arange(knots.size) / (knots.size - 1))
    target = density.probabilities.reshape(bands.band_count, -1).sum(axis=1)
    np.testing.assert_allclose(np.diff(band_cdf), target, rtol=3e-3)
    count = 400_000
    wavelengths, ratios, band_of_lane = _draw(bands, density, count, seed=5)
    # Bins: half cells of the tabulated density, expected N·∫_bin p over the table's piecewise-linear CDF.
    bin_edges = np.linspace(
        bands.wavelength_min_nm, bands.wavelength_max_nm, 2 * density.probabilities.size + 1
    )
    probabilities = np.diff(np.interp(bin_edges, knots, np.arange(knots.size) / (knots.size - 1)))
    level = sidak_level(0.01, 2)
    for lane in (0, 2):  # lanes are rotations of one number: each is an i.i.d. sequence of its own
        observed, _ = np.histogram(wavelengths[lane], bins=bin_edges)
        result = discrete_chi2(observed, probabilities)
        assert result.passes(level), (lane, result)
        # The same counts are far from a uniform draw: the test can tell the two apart.
        uniform = np.full(probabilities.size, 1.0 / probabilities.size)
        assert not discrete_chi2(observed, uniform).passes(level)
    # Each lane's ratio is (1/Λ)/p at its λ, away from the knots (where float32 λ may round across).
    span = bands.wavelength_max_nm - bands.wavelength_min_nm
    knots64 = knots.astype(np.float64)
    above = np.clip(np.searchsorted(knots64, wavelengths), 1, knots.size - 1)
    nearest = np.minimum(np.abs(wavelengths - knots64[above - 1]), np.abs(knots64[above] - wavelengths))
    clear = nearest > 1e-4
    assert clear.mean() > 0.99
    expected_ratios = 1.0 / (span * knot_pdf_nm(knots, wavelengths))
    np.testing.assert_allclose(ratios[clear], expected_ratios[clear], rtol=2e-5)
    expected_band = np.clip(np.floor((wavelengths - bands.wavelength_min_nm) / bands.width_nm), 0, 15)
    np.testing.assert_array_equal(band_of_lane, expected_band)
    assert np.mean(ratios) == pytest.approx(1.0, abs=0.02)  # E_p[(1/Λ)/p] = 1


def _render(scene: dict, mode: str, seed: int):
    scene = {**scene, "film": {**scene["film"], "wavelength_sampling": mode}}
    mi = configured_mitsuba()
    compiled = SceneCompiler(mi, limits=SceneLimits()).compile(validate_scene(scene))
    sums = Renderer(compiled).render_sums(scene["film"]["spp"], seed)
    return images_from_sums(sums, compiled.bands)


def _plane(spp: int, size_px: int = 32) -> dict:
    scene = plane_under_source(F11_SPHERE, size_px=size_px, spp=spp)
    scene["film"]["bands"] = 16
    return scene


def test_importance_agrees_with_uniform_per_band() -> None:
    scene = _plane(spp=64, size_px=24)
    means, errors = {}, {}
    for mode in ("uniform", "importance"):
        images = _render(scene, mode, seed=7)
        pixels = images["bands"].shape[0] * images["bands"].shape[1]
        means[mode] = images["bands"].astype(np.float64).mean(axis=(0, 1))
        errors[mode] = np.sqrt(images["band_variance"].astype(np.float64).sum(axis=(0, 1))) / pixels
    combined = np.sqrt(errors["uniform"] ** 2 + errors["importance"] ** 2)
    z_scores = (means["importance"] - means["uniform"]) / combined
    print("z", np.round(z_scores, 2), "\nrel SE", np.round(errors["importance"] / means["importance"], 4))
    assert np.all(errors["importance"] <= 0.05 * means["importance"])  # tight enough to see a few % bias
    assert np.all(np.abs(z_scores) <= 4.0), np.round(z_scores, 2)


def _chroma_deviations(images: dict) -> np.ndarray:
    """Per pixel (a* − ā*)² + (b* − b̄*)², CIELAB relative to the patch's mean luminance as white."""
    rgb = images["rgb"].reshape(-1, 3).astype(np.float64)
    lab = linear_srgb_to_lab(rgb, white_level=float(rgb[:, 1].mean()))
    chroma = lab[:, 1:]
    return np.sum((chroma - chroma.mean(axis=0)) ** 2, axis=1)


def test_importance_lowers_chroma_variance_under_f11() -> None:
    scene = _plane(spp=16)
    uniform = _chroma_deviations(_render(scene, "uniform", seed=3))
    importance = _chroma_deviations(_render(scene, "importance", seed=3))
    ratio = uniform.mean() / importance.mean()
    # Relative SE of each variance estimate: std of the squared deviations / (mean·√P); of the ratio: both.
    relative_error = math.hypot(
        uniform.std() / (uniform.mean() * math.sqrt(uniform.size)),
        importance.std() / (importance.mean() * math.sqrt(importance.size)),
    )
    print(
        f"chroma variance uniform {uniform.mean():.1f}, importance {importance.mean():.1f}, ratio {ratio:.2f}"
    )
    assert ratio * (1.0 - 3.0 * relative_error) >= 2.0, (ratio, relative_error)


def test_cornell_box_under_f11_matches_path(tmp_path: Path) -> None:
    from tests.support.reference import assert_agreement

    scene = example("cornell_box", width=32, height=32, spp=512, bands=8, max_depth=5)
    for emitter in scene["emitters"]:
        emitter["spectrum"] = {"type": "cie_f", "name": "F11"}
    assert sampling_mode(validate_scene(scene)) == "importance"  # the default, auto, sees F11's lines
    assert_agreement(scene, tmp_path, path_spp=128)
