"""``hgrender render`` end to end through the installed console script."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from tests.support.scenes import example

HGRENDER = Path(sys.executable).parent / "hgrender"


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(HGRENDER), *args], capture_output=True, text=True, timeout=600, check=False)


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
