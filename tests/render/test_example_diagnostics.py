"""Every example's coherence diagnostics are valid (issue 26): finite, ℓ and area ≥ 0, and M positive
semidefinite in every pixel — a weighted mean of M = (k/r)²Σ⊥ ≥ 0 with weights ≥ 0 is one, and so must the
written estimate be, whatever the rounding of the float32 sums it comes from."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hgcore.artifacts.exr import read_exr
from hgcore.artifacts.images import secondary_source_m
from hgcore.optics.coherence import positive_semidefinite_components
from schemas import EXAMPLES_DIR, validate_scene
from tests.support.scenes import tiny_scene
from worker.render.chunks import render_scene

# A rotation taking +z to (0.6, 0.48, 0.64): columns an orthonormal basis (e₁, e₂, mean direction).
_MEAN = np.array([0.6, 0.48, 0.64])
_E1 = np.cross([0.0, 0.0, 1.0], _MEAN) / np.linalg.norm(np.cross([0.0, 0.0, 1.0], _MEAN))
OBLIQUE = np.column_stack([_E1, np.cross(_MEAN, _E1), _MEAN])
EXAMPLES = sorted(path.stem for path in EXAMPLES_DIR.glob("*.json"))


def assert_valid_diagnostics(channels: dict[str, np.ndarray], where: str) -> None:
    for name, values in channels.items():
        if name.startswith("coherence."):
            assert np.all(np.isfinite(values)), (where, name)
    for name in ("l1_um", "l2_um", "area_um2", "anisotropy", "r_m", "weight", "Mxx", "Myy"):
        assert channels[f"coherence.{name}"].min() >= 0.0, (where, name)
    m_xx, m_xy, m_yy = (channels[f"coherence.M{k}"].astype(np.float64) for k in ("xx", "xy", "yy"))
    # float32 files: the determinant of a PSD rank-one M rounds to ±1e-7 of m_xx·m_yy
    assert np.all(m_xx * m_yy - m_xy * m_xy >= -1e-6 * m_xx * m_yy), where


@pytest.mark.parametrize("name", EXAMPLES)
def test_every_example_writes_valid_coherence_diagnostics(name: str, tmp_path: Path) -> None:
    render_scene(validate_scene(tiny_scene(name, size_px=24, spp=8)), tmp_path, chunks=2)
    assert_valid_diagnostics(read_exr(tmp_path / "image.exr").channels, name)


def test_a_secondary_source_seen_along_one_direction_stays_positive_semidefinite() -> None:
    """Arrival directions that agree to 1e-4 rad, summed in float32 as the renderer does: second − mean²
    cancels to rounding noise (|noise| ≫ the true covariance of 1e-8 rad², and of either sign), which
    k² ≈ 1.3e14/m² makes |M| ≈ 1e5; the estimate must still be PSD, and close to the truth where the
    truth is larger than the noise (the transverse spread below is 1e-2 rad)."""
    rng = np.random.default_rng(7)
    for spread_rad in (1e-4, 1e-2):
        count = 256
        transverse = rng.normal(0.0, spread_rad, (count, 2))
        directions = np.column_stack([transverse, np.ones(count)])
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        # oblique in camera coordinates, as a source off the axis is: every raw moment is O(1) and cancels
        directions = directions @ OBLIQUE.T
        weights = rng.uniform(0.5, 1.5, count)
        values: dict[str, np.ndarray] = {
            "vcz_w": weights.sum(),
            "vcz_w2": (weights**2).sum(),
            "vcz_r": weights.sum(),
        }
        for i, a in enumerate("xyz"):
            values[f"vcz_d{a}"] = np.float32(0.0)
            for j in range(i, 3):
                values[f"vcz_d{a}{'xyz'[j]}"] = np.float32(0.0)
        for w, d in zip(weights.astype(np.float32), directions.astype(np.float32), strict=True):
            for i, a in enumerate("xyz"):
                values[f"vcz_d{a}"] = np.float32(values[f"vcz_d{a}"] + w * d[i])
                for j in range(i, 3):
                    key = f"vcz_d{a}{'xyz'[j]}"
                    values[key] = np.float32(values[key] + w * d[i] * d[j])
        arrays = {key: np.full((1, 1), float(value)) for key, value in values.items()}
        m_xx, m_xy, m_yy = (component[0, 0] for component in secondary_source_m(arrays).m_per_m2)
        assert m_xx >= 0.0 and m_yy >= 0.0 and m_xx * m_yy - m_xy**2 >= -1e-9 * m_xx * m_yy, spread_rad
        if spread_rad == 1e-2:
            expected = (2 * np.pi / 550e-9) ** 2 * spread_rad**2
            assert m_xx == pytest.approx(expected, rel=0.3) and m_yy == pytest.approx(expected, rel=0.3)


def test_the_projection_is_the_nearest_positive_semidefinite_matrix() -> None:
    """Eigenvalues clipped at 0 in the eigenbasis: a PSD matrix is unchanged, diag(2, −1) rotated becomes
    its rank-one part, −I becomes 0."""
    angle = 0.3
    c, s = np.cos(angle), np.sin(angle)
    rotated = (2 * c * c - s * s, 3 * c * s, 2 * s * s - c * c)
    np.testing.assert_allclose(positive_semidefinite_components(*rotated), (2 * c * c, 2 * c * s, 2 * s * s))
    np.testing.assert_allclose(positive_semidefinite_components(2.0, 0.5, 1.0), (2.0, 0.5, 1.0))
    np.testing.assert_allclose(positive_semidefinite_components(-1.0, 0.0, -1.0), (0.0, 0.0, 0.0))
