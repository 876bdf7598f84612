"""Coherence calculator (issue 2 item 7): ``coherence_at`` per source and the ``hgrender coherence`` CLI."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hgcore.optics.calculator import coherence_at

REPO = Path(__file__).resolve().parents[2]
HGRENDER = REPO / ".venv" / "bin" / "hgrender"
K = 2 * math.pi / 550e-9
KEYS = {
    "l1_um",
    "l2_um",
    "anisotropy",
    "angle",
    "area_um2",
    "r_m",
    "theta",
    "sigma_m2",
    "M",
    "coefficients",
    "wavelength_nm",
    "source",
    "frame",
}


@pytest.mark.parametrize(
    ("source", "sizes", "sigma_expected"),
    [
        ("sphere", {"radius_m": 0.01}, np.diag([0.01**2 / 4, 0.01**2 / 4])),
        ("gaussian", {"sigma_m": 0.002}, np.diag([0.002**2, 0.002**2])),
        ("cylinder", {"radius_m": 0.001, "length_m": 0.2}, np.diag([0.2**2 / 12, 0.001**2 / 3])),
        ("disk", {"radius_m": 0.01}, np.diag([0.01**2 / 4, 0.01**2 / 4])),  # face-on about the x axis
        ("rect", {"width_m": 0.03, "height_m": 0.01}, np.diag([0.03**2 / 12, 0.01**2 / 12])),
    ],
)
def test_calculator_json_per_source(source: str, sizes: dict, sigma_expected: np.ndarray) -> None:
    # Default axis (1,0,0) and direction (0,0,1): every source is seen face-on / side-on, so Σ⊥ is the
    # closed form in the world x/y frame and ℓ = r/(k·s) along each axis (1/√e half-widths).
    r = 0.75
    result = coherence_at(source, distance_m=r, modes=4, **sizes)
    assert set(result) >= KEYS
    json.dumps(result)  # JSON-ready
    np.testing.assert_allclose(result["sigma_m2"], sigma_expected, rtol=1e-12, atol=0.0)
    np.testing.assert_allclose(np.array(result["theta"]) @ sigma_expected, np.eye(2), atol=1e-12)
    np.testing.assert_allclose(result["M"], (K / r) ** 2 * sigma_expected, rtol=1e-12)
    lengths = sorted(1e6 * r / (K * math.sqrt(v)) for v in np.diag(sigma_expected))
    assert result["l1_um"] == pytest.approx(lengths[1], rel=1e-12)
    assert result["l2_um"] == pytest.approx(lengths[0], rel=1e-12)
    assert result["area_um2"] == pytest.approx(math.pi * lengths[0] * lengths[1], rel=1e-12)
    assert result["anisotropy"] == pytest.approx(lengths[1] / lengths[0], rel=1e-12)
    assert [(c["n"], c["m"]) for c in result["coefficients"]] == [(0, 0), (2, 0), (1, 1), (0, 2)]
    assert result["frame"] == {
        "x_axis": [1.0, 0.0, 0.0],
        "y_axis": [0.0, 1.0, 0.0],
        "direction": [0.0, 0.0, 1.0],
    }


def test_wavelength_scales_lengths() -> None:
    # ℓ = r λ/(2π s) ∝ λ.
    at_550 = coherence_at("sphere", radius_m=0.01, distance_m=1.0)
    at_1100 = coherence_at("sphere", radius_m=0.01, distance_m=1.0, wavelength_nm=1100)
    assert at_1100["l1_um"] / at_550["l1_um"] == pytest.approx(2.0, rel=1e-12)


def test_oblique_cylinder_angle_and_frame() -> None:
    # Axis in the transverse plane at 30° from x: side-on strip, ℓ₁ (across the axis) at 30° + 90° → −60°.
    axis = (math.cos(math.radians(30)), math.sin(math.radians(30)), 0.0)
    result = coherence_at("cylinder", radius_m=0.001, length_m=0.2, distance_m=0.6, axis=axis)
    assert result["angle"] == pytest.approx(math.radians(-60.0), abs=1e-12)
    assert result["anisotropy"] == pytest.approx(0.2 / math.sqrt(12) / (0.001 / math.sqrt(3)), rel=1e-9)
    # Seen along world x, the frame's x axis is the projection of world y.
    along_x = coherence_at("sphere", radius_m=0.01, distance_m=1.0, direction=(2.0, 0.0, 0.0))
    assert along_x["frame"]["x_axis"] == [0.0, 1.0, 0.0]
    assert along_x["frame"]["direction"] == [1.0, 0.0, 0.0]


@pytest.mark.parametrize(
    ("kwargs", "parameter"),
    [
        ({"source": "sphere", "distance_m": 1.0}, "radius_m"),
        ({"source": "sphere", "radius_m": -0.1, "distance_m": 1.0}, "radius_m"),
        ({"source": "sphere", "radius_m": 0.1, "distance_m": 0.0}, "distance_m"),
        ({"source": "sphere", "radius_m": 0.1, "distance_m": float("nan")}, "distance_m"),
        ({"source": "sphere", "radius_m": 0.1, "distance_m": 1.0, "wavelength_nm": 199.0}, "wavelength_nm"),
        ({"source": "sphere", "radius_m": 0.1, "distance_m": 1.0, "wavelength_nm": 2501.0}, "wavelength_nm"),
        ({"source": "sphere", "radius_m": 0.1, "distance_m": 1.0, "modes": 65}, "modes"),
        ({"source": "sphere", "radius_m": 0.1, "distance_m": 1.0, "direction": (0, 0, 0)}, "direction"),
        ({"source": "rect", "width_m": 0.1, "height_m": 0.1, "distance_m": 1.0, "axis": (0, 0, 1)}, "axis"),
        ({"source": "star", "radius_m": 0.1, "distance_m": 1.0}, "source"),
    ],
)
def test_calculator_invalid_inputs(kwargs: dict, parameter: str) -> None:
    source = kwargs.pop("source")
    with pytest.raises(ValueError, match=rf"^{parameter}:"):
        coherence_at(source, **kwargs)


def test_nearly_edge_on_disk_is_strongly_anisotropic() -> None:
    # Diameter tilted 1e-5 rad from the line of sight: the disk's normal is at 90° − 1e-5 rad, foreshortened
    # by cos θ = |u⊥| ≈ 1e-5, so anisotropy = 1/cos θ ≈ 1e5 (exactly edge-on is rejected, see above).
    tilt = 1e-5
    result = coherence_at("disk", radius_m=0.1, distance_m=1.0, axis=(math.sin(tilt), 0.0, math.cos(tilt)))
    assert result["anisotropy"] == pytest.approx(1 / math.sin(tilt), rel=1e-6)


def run_cli(*arguments: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [str(HGRENDER), "coherence", *arguments], capture_output=True, text=True, timeout=120, check=False
    )


def test_cli_json_matches_library() -> None:
    completed = run_cli(
        "--source", "cylinder", "--radius", "0.001", "--length", "0.2", "--distance", "0.6",
        "--axis", "1,0.2,0.1", "--direction", "0,0.1,1", "--modes", "9", "--json",
    )  # fmt: skip
    assert completed.returncode == 0, completed.stderr
    printed = json.loads(completed.stdout)
    expected = coherence_at(
        "cylinder",
        radius_m=0.001,
        length_m=0.2,
        distance_m=0.6,
        axis=(1, 0.2, 0.1),
        direction=(0, 0.1, 1),
        modes=9,
    )
    assert printed.keys() == expected.keys()
    for key in ("l1_um", "l2_um", "anisotropy", "angle", "area_um2", "r_m", "wavelength_nm"):
        assert printed[key] == pytest.approx(expected[key], rel=1e-15)
    np.testing.assert_allclose(printed["theta"], expected["theta"], rtol=1e-15)
    assert len(printed["coefficients"]) == 9


def test_cli_table_without_json() -> None:
    completed = run_cli("--source", "sphere", "--radius", "0.006", "--distance", "0.6")
    assert completed.returncode == 0, completed.stderr
    assert "l1" in completed.stdout and "17.507" in completed.stdout


@pytest.mark.parametrize(
    ("arguments", "flag"),
    [
        (["--source", "sphere", "--radius", "-1", "--distance", "1"], "--radius"),
        (["--source", "sphere", "--radius", "nan", "--distance", "1"], "--radius"),
        (["--source", "cylinder", "--radius", "0.1", "--distance", "1"], "--length"),
        (["--source", "sphere", "--radius", "0.1", "--distance", "0"], "--distance"),
        (
            ["--source", "sphere", "--radius", "0.1", "--distance", "1", "--wavelength-nm", "3000"],
            "--wavelength-nm",
        ),
        (["--source", "sphere", "--radius", "0.1", "--distance", "1", "--modes", "0"], "--modes"),
        (["--source", "sphere", "--radius", "0.1", "--distance", "1", "--direction", "0,0,0"], "--direction"),
        (["--source", "disk", "--radius", "0.1", "--distance", "1", "--axis", "0,0,1"], "--axis"),
    ],
)
def test_cli_invalid_inputs_exit_2_naming_the_flag(arguments: list[str], flag: str) -> None:
    completed = run_cli(*arguments, "--json")
    assert completed.returncode == 2
    assert f"error: {flag}" in completed.stderr
    assert completed.stdout == ""


def test_calculator_never_imports_mitsuba_or_drjit() -> None:
    # The service calls coherence_at in-process and must not load Mitsuba/Dr.Jit, even transitively.
    code = (
        "import sys, hgcore.optics.calculator as c, hgrender.cli.coherence;"
        "c.coherence_at('cylinder', radius_m=1e-3, length_m=0.2, distance_m=0.6, modes=16);"
        "bad = [m for m in sys.modules if m.split('.')[0] in ('mitsuba', 'drjit')]; assert not bad, bad"
    )
    completed = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=120
    )
    assert completed.returncode == 0, completed.stderr
