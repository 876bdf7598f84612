"""``hgrender render`` end to end through the installed console script."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from schemas import validate_scene
from schemas.usd_export import scene_to_usd
from tests.support.scenes import example

HGRENDER = Path(sys.executable).parent / "hgrender"


def run(*args: str, **env: str) -> subprocess.CompletedProcess:
    """``hgrender ARGS`` with ``env`` added to this process's environment."""
    return subprocess.run(
        [str(HGRENDER), *args],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
        env={**os.environ, **env},
    )


def test_render_writes_artifacts_and_reports_json(tmp_path: Path) -> None:
    scene = example("cornell_box", width=12, height=12)
    scene_path = tmp_path / "scene.json"
    scene_path.write_text(json.dumps(scene))
    result = run(
        "render", str(scene_path), "-o", str(tmp_path / "out"), "--spp", "3", "--seed", "5", "--chunks", "2"
    )
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout.strip().splitlines()[-1])
    assert report["spp"] == 3
    assert set(report["files"]) >= {"image.exr", "variance.exr", "preview.png", "summary.json"}
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert (summary["spp"], summary["chunks"], summary["width"]) == (3, 2, 12)
    assert "100%" in result.stderr  # the progress bar reached its end


def test_render_rejects_bad_input_naming_the_field(tmp_path: Path) -> None:
    scene = example("cornell_box", bands=0)
    scene_path = tmp_path / "bad.json"
    scene_path.write_text(json.dumps(scene))
    result = run("render", str(scene_path), "-o", str(tmp_path / "out"))
    assert result.returncode == 2
    assert "/film/bands" in result.stderr
    assert not (tmp_path / "out").exists()  # nothing half-done
    missing = run("render", str(tmp_path / "nope.json"), "-o", str(tmp_path / "out"))
    assert missing.returncode == 2 and "no such file" in missing.stderr


def test_render_of_a_usd_stage_checks_it_against_the_processs_settings(tmp_path: Path) -> None:
    """A USD stage is imported under the command's settings (built before anything else) and its
    ``--spp`` override is checked against the same settings."""
    usd_path = scene_to_usd(
        validate_scene(example("cornell_box", width=8, height=8, spp=2)), tmp_path / "s.usda"
    )
    out = tmp_path / "out"
    result = run("render", str(usd_path), "-o", str(out), "--spp", "1")
    assert result.returncode == 0, result.stderr
    assert json.loads((out / "summary.json").read_text())["width"] == 8
    too_large = run("render", str(usd_path), "-o", str(tmp_path / "a"), HGRENDER_MAX_PIXELS="63")
    assert too_large.returncode == 2 and "HGRENDER_MAX_PIXELS" in too_large.stderr, too_large.stderr
    too_many = run("render", str(usd_path), "-o", str(tmp_path / "b"), "--spp", "5", HGRENDER_MAX_SPP="4")
    assert too_many.returncode == 2, too_many.stderr
    assert "/film/spp: spp 5 exceeds the limit of 4" in too_many.stderr, too_many.stderr
