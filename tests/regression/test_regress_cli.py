"""``hgrender regress``: a suite rendered again with different seeds passes (noise only); deliberate changes
fail, naming the scene and the metric, while the unchanged scene still passes; JUnit XML; exit codes.

Tiny renders (16×16 px, 8 spp, 8 bands: about 0.1 s each after the first kernel compilation) of two scenes:

* ``thin_film`` (Fig. 7, thin film under a sphere light of radius 6 mm): doubling the light's radius halves
  the coherence lengths ℓ₁, ℓ₂ (van Cittert–Zernike: ℓ ∝ distance / radius) in every covered pixel, so the
  coherence sign test has z ≈ −√n ≈ −10 for n ≈ 100 covered pixels, far beyond z_crit = 5.
* ``cornell_box``: the white walls' reflectance 0.75 → 0.4 darkens every band by ≈ 30 % (measured 28-40 %
  over seeds 2-5, z 7.5-9.6 in the per-pixel test), far above the 5 % effect-size threshold.

(A thin-film thickness change in the Fig. 7 scene is not used: at this size only ~4 highlight pixels show
the film, and their ≈ 5 % spectral change is below the noise of 8 spp, so the noise-aware test rightly
passes it; detecting it needs more pixels on the highlight or more samples.)
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import pytest

from hgrender.cli import main

EXAMPLES = Path(__file__).parents[2] / "schemas" / "examples"


def write_suite(path: Path, light_radius_m: float = 0.006, white_reflectance: float = 0.75) -> Path:
    thin_film = json.loads((EXAMPLES / "thin_film_sphere_light.json").read_text())
    thin_film["emitters"][0]["radius_m"] = light_radius_m
    cornell = json.loads((EXAMPLES / "cornell_box.json").read_text())
    cornell["materials"]["white"]["reflectance"] = white_reflectance
    overrides: dict[str, Any] = {"spp": 8, "width": 16, "height": 16}
    for scene in (thin_film, cornell):
        scene["film"]["bands"] = 8
    suite = {
        "scenes": [
            {"name": "thin_film", "scene": thin_film, **overrides},
            {"name": "cornell_box", "scene": cornell, **overrides},
        ]
    }
    path.write_text(json.dumps(suite))
    return path


def regress(*args: str) -> int:
    return main(["regress", *args])


@pytest.fixture()
def baseline_dir(tmp_path: Path) -> Path:
    suite = write_suite(tmp_path / "suite.json")
    baseline = tmp_path / "baselines"
    assert regress(str(suite), "--baseline", str(baseline), "--update-baseline", "--seed", "1") == 0
    for scene in ("thin_film", "cornell_box"):
        assert (baseline / scene / "image.exr").is_file() and (baseline / scene / "variance.exr").is_file()
    return baseline


def test_rerender_with_other_seeds_passes(
    tmp_path: Path, baseline_dir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    suite = write_suite(tmp_path / "suite.json")
    junit = tmp_path / "report.xml"
    for seed in ("2", "3"):
        code = regress(str(suite), "--baseline", str(baseline_dir), "--seed", seed, "--junit", str(junit))
        table = capsys.readouterr().out
        assert code == 0, table
        assert f"{'thin_film':<28} pass" in table and f"{'cornell_box':<28} pass" in table
    report = ET.parse(junit).getroot()
    assert report.get("tests") == "2" and report.get("failures") == "0" and report.get("errors") == "0"


def test_larger_light_fails_the_thin_film_on_coherence(
    tmp_path: Path, baseline_dir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    suite = write_suite(tmp_path / "changed.json", light_radius_m=0.012)
    junit = tmp_path / "report.xml"
    code = regress(str(suite), "--baseline", str(baseline_dir), "--seed", "4", "--junit", str(junit))
    table = capsys.readouterr().out
    assert code == 1, table
    assert "thin_film: coherence_drift of l1_um" in table
    assert f"{'cornell_box':<28} pass" in table
    report = ET.parse(junit).getroot()
    assert report.get("failures") == "1"
    failure = report.find("testcase[@name='thin_film']/failure")
    assert failure is not None and "thin_film: coherence_drift of l2_um" in (failure.get("message") or "")


def test_darker_walls_fail_the_cornell_box_on_band_means(
    tmp_path: Path, baseline_dir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    suite = write_suite(tmp_path / "changed.json", white_reflectance=0.4)
    code = regress(str(suite), "--baseline", str(baseline_dir), "--seed", "5")
    table = capsys.readouterr().out
    assert code == 1, table
    assert "cornell_box: rel_mean_change of band" in table
    assert f"{'thin_film':<28} pass" in table


def test_missing_baseline_is_an_error_exit(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    suite = write_suite(tmp_path / "suite.json")
    assert regress(str(suite), "--baseline", str(tmp_path / "none"), "--seed", "1") == 1
    assert "thin_film: no baseline" in capsys.readouterr().out


def test_invalid_suite_names_the_field(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    suite = tmp_path / "bad.yaml"
    suite.write_text("scenes:\n  - example: cornell_box\n    job_id: abc\n")
    assert regress(str(suite)) == 2
    assert "suite: scenes.0" in capsys.readouterr().err
