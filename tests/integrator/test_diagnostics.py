"""Per-pixel coherence diagnostics of ``hg_path`` against the optics core's coherence calculator.

A diffuse plane z = 0 is lit only by one source above it and seen from straight above, so the light
incident at every visible plane point comes from that source alone and its diagnostics must equal the
calculator's for the geometry (source centre → plane point). Within a pixel the geometry varies by less
than 0.1 %, so the BRIEF's 2 % tolerance is far above the in-pixel spread; float32 storage adds ~1e-7.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from hgcore.artifacts.exr import read_exr
from hgcore.optics.calculator import coherence_at
from schemas import validate_scene
from tests.integrator.scenes import plane_under_source
from worker.render.chunks import render_scene

SIZE = 24
CAMERA_HEIGHT_M = 3.0
FOV_DEG = 20.0


def channels(path: Path) -> dict[str, np.ndarray]:
    return read_exr(path).channels


def plane_points() -> np.ndarray:
    """World positions (x, y, 0) of the pixel centres on the plane (up to the sign of x and y)."""
    half = math.tan(math.radians(FOV_DEG / 2)) * CAMERA_HEIGHT_M
    coordinates = (np.arange(SIZE) + 0.5) / SIZE * 2 * half - half
    x, y = np.meshgrid(coordinates, -coordinates)
    return np.stack([x, y, np.zeros_like(x)], axis=-1)


def lit_plane_pixels(data: dict[str, np.ndarray], first: int) -> list[tuple[int, int, np.ndarray]]:
    """(row, column, plane point) of every third pixel from ``first`` that shows the plane with diagnostics
    (not the source itself, which is nearer than 3 m)."""
    points = plane_points()
    return [
        (row, column, points[row, column])
        for row in range(first, SIZE, 3)
        for column in range(first, SIZE, 3)
        if data["coherence.weight"][row, column] > 0 and abs(data["depth"][row, column] - 3.0) <= 0.2
    ]


def expected(source: str, center: np.ndarray, point: np.ndarray, **sizes: float) -> dict:
    offset = point - center
    return coherence_at(
        source,
        distance_m=float(np.linalg.norm(offset)),
        direction=tuple(offset / np.linalg.norm(offset)),
        **sizes,
    )


def test_sphere_source_diagnostics_match_the_calculator(tmp_path: Path) -> None:
    center = np.array([0.0, 0.0, 1.0])
    radius = 0.02
    scene = plane_under_source(
        {
            "type": "sphere",
            "center_m": center.tolist(),
            "radius_m": radius,
            "spectrum": {"type": "d65"},
            "power_w": 20.0,
        },
        size_px=SIZE,
        spp=4,
    )
    render_scene(validate_scene(scene), tmp_path)
    data = channels(tmp_path / "image.exr")
    pixels = lit_plane_pixels(data, 0)
    for row, column, point in pixels:
        reference = expected("sphere", center, point, radius_m=radius)
        assert math.isclose(data["coherence.r_m"][row, column], reference["r_m"], rel_tol=0.02)
        assert math.isclose(data["coherence.l1_um"][row, column], reference["l1_um"], rel_tol=0.02)
        assert math.isclose(data["coherence.l2_um"][row, column], reference["l2_um"], rel_tol=0.02)
        assert math.isclose(data["coherence.area_um2"][row, column], reference["area_um2"], rel_tol=0.04)
    assert len(pixels) >= 40


def test_cylinder_source_anisotropy_and_orientation_match_the_calculator(tmp_path: Path) -> None:
    # A cylinder along world x, 1 m above the plane: side-on from the plane it is a strip L × 2R, so the
    # coherence is long across the axis (ℓ₁ along y: vertical on screen) and short along it.
    radius, length = 0.01, 0.4
    center = np.array([0.0, 0.0, 1.0])
    scene = plane_under_source(
        {
            "type": "cylinder",
            "p0_m": [-length / 2, 0.0, 1.0],
            "p1_m": [length / 2, 0.0, 1.0],
            "radius_m": radius,
            "spectrum": {"type": "d65"},
            "power_w": 20.0,
        },
        size_px=SIZE,
        spp=4,
    )
    render_scene(validate_scene(scene), tmp_path)
    data = channels(tmp_path / "image.exr")
    pixels = lit_plane_pixels(data, 1)
    for row, column, point in pixels:
        reference = expected(
            "cylinder", center, point, radius_m=radius, length_m=length, axis=(1.0, 0.0, 0.0)
        )
        assert math.isclose(data["coherence.anisotropy"][row, column], reference["anisotropy"], rel_tol=0.02)
        assert math.isclose(data["coherence.l1_um"][row, column], reference["l1_um"], rel_tol=0.02)
        assert math.isclose(data["coherence.l2_um"][row, column], reference["l2_um"], rel_tol=0.02)
        # ℓ₁ axis ⟂ to the cylinder axis: vertical on screen, |angle| = π/2 (angles are mod π).
        angle = float(data["coherence.angle"][row, column])
        assert abs(abs(angle) - math.pi / 2) < math.radians(3.0), angle
    assert len(pixels) >= 30
    assert reference["anisotropy"] > 5.0  # the test geometry is strongly anisotropic
