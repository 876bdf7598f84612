"""``hgrender regress``: a suite rendered twice with different seeds passes (noise only); a deliberate
change (a light's radius) fails, naming the scene and the metric; JUnit XML and exit codes.

Tiny renders (16×16 px, 8 spp, 8 bands: about 0.1 s each after the first kernel compilation). The thin film
under a sphere light (Fig. 7) is the scene: its sphere light of radius 6 mm gives the coherence the metric
watches (ℓ ∝ distance / radius by van Cittert-Zernike), so doubling the radius halves ℓ₁ and ℓ₂ in every
covered pixel; the sign test then has z ≈ √n ≈ 10 for n ≈ 100 covered pixels, far above z_crit = 5.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from hgrender.cli import main

SCENE_NAME = "thin_film"


def write_suite(path: Path, light_radius_m: float | None = None) -> Path:
    scene = json.loads(
        (Path(__file__).parents[2] / "schemas/examples/thin_film_sphere_light.json").read_text()
    )
    scene["film"]["bands"] = 8
    if light_radius_m is not None:
        scene["emitters"][0]["radius_m"] = light_radius_m
    suite = {"scenes": [{"name": SCENE_NAME, "scene": scene, "spp": 8, "width": 16, "height": 16}]}
    path.write_text(json.dumps(suite))
    return path


@pytest.fixture()
def baseline_dir(tmp_path: Path) -> Path:
    suite = write_suite(tmp_path / "suite.json")
    baseline = tmp_path / "baselines"
    assert main(["regress", str(suite), "--baseline", str(baseline), "--update-baseline", "--seed", "1"]) == 0
    assert (baseline / SCENE_NAME / "image.exr").is_file() and (
        baseline / SCENE_NAME / "variance.exr"
    ).is_file()
    return baseline


def test_rerender_with_another_seed_passes(
    tmp_path: Path, baseline_dir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    suite = write_suite(tmp_path / "suite.json")
    junit = tmp_path / "report.xml"
    for seed in (2, 3):
        code = main(
            [
                "regress",
                str(suite),
                "--baseline",
                str(baseline_dir),
                "--seed",
                str(seed),
                "--junit",
                str(junit),
            ]
        )
        table = capsys.readouterr().out
        assert code == 0, table
        assert f"{SCENE_NAME:<28} pass" in table
    report = ET.parse(junit).getroot()
    assert report.get("tests") == "1" and report.get("failures") == "0" and report.get("errors") == "0"


def test_larger_light_fails_naming_scene_and_metric(
    tmp_path: Path, baseline_dir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    suite = write_suite(tmp_path / "changed.json", light_radius_m=0.012)
    junit = tmp_path / "report.xml"
    code = main(
        ["regress", str(suite), "--baseline", str(baseline_dir), "--seed", "4", "--junit", str(junit)]
    )
    table = capsys.readouterr().out
    assert code == 1, table
    assert f"{SCENE_NAME}: coherence_drift of l1_um" in table
    failure = ET.parse(junit).getroot().find("testcase/failure")
    assert failure is not None and f"{SCENE_NAME}: coherence_drift of l2_um" in (failure.get("message") or "")


def test_missing_baseline_is_an_error_exit(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    suite = write_suite(tmp_path / "suite.json")
    assert main(["regress", str(suite), "--baseline", str(tmp_path / "none"), "--seed", "1"]) == 1
    assert "no baseline" in capsys.readouterr().out


def test_invalid_suite_names_the_field(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    suite = tmp_path / "bad.yaml"
    suite.write_text("scenes:\n  - example: cornell_box\n    job_id: abc\n")
    assert main(["regress", str(suite)]) == 2
    assert "suite: scenes.0" in capsys.readouterr().err
