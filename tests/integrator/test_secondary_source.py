"""The coherence of light from a diffuse surface is van Cittert–Zernike's for its lit, seen part.

A small floor patch (the receiver) is lit only by a diffuse square of side a at distance d: the one-sided
emitter faces the square from out of the receiver's sight and the receiver lies behind its plane. The
square is therefore an incoherent secondary source of radiance ρE(x)/π, and the light the receiver gets
from it has M = k²·Cov(ω⊥) (docs/physics.md §7), where ω⊥ are the arrival directions weighted by
L cos θ_r dω. The reference evaluates that integral by midpoint quadrature over the square and the emitter
(independent of the renderer: irradiance E from the emitter's geometry, no Monte Carlo).

Error model. Each pixel's M is a weighted sample covariance of its paths' arrival directions (unbiased with
the effective-sample-count correction); its eigenvalues are biased apart by O(1/n_eff), so the test
averages M over the pixels first and compares eigenvalues of the mean, whose standard error comes from the
pixel-to-pixel scatter (4 SE). The pixels' receiver points spread over ±1 cm of the floor, which moves ℓ by
≲ 0.4 % (ℓ ∝ d, d ≈ 2.7 m) and averages to < 0.1 %; the quadrature's midpoint error is < 1e-4. Float32
sums of w·ddᵀ lose ≈ 1e-7/Var(ω) ≈ 1e-4 relative here.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from hgcore.artifacts.exr import read_exr
from schemas import build, validate_scene
from worker.render.chunks import render_scene

K_PER_M = 2 * math.pi / 550e-9
PATCH_CENTRE = np.array([-0.5, 1.0, 0.0])
EMITTER_CENTRE = np.array([0.5, 1.0, 0.6])
EMITTER_NORMAL = np.array([-1.0, 0.0, -0.6]) / math.hypot(1.0, 0.6)
EMITTER_SIDE_M = 0.3
UP = np.array([0.0, 1.0, 0.0])


def scene(side_m: float, receiver_x_m: float) -> dict:
    return build.scene(
        "floor lit by a diffuse square",
        camera=build.camera([receiver_x_m, 0.3, 0.0], [receiver_x_m, 0.0, 0.0], up=[0, 0, -1], fov_deg=4.0),
        film=build.film(6, bands=4, spp=65536, max_depth=3),
        materials={
            "floor": {"type": "diffuse", "reflectance": 0.5},
            "square": {"type": "diffuse", "reflectance": 0.8},
        },
        shapes=[
            build.rectangle(
                [receiver_x_m, 0.0, 0.0], normal=[0, 1, 0], up=[0, 0, -1], width_m=0.5, material="floor"
            ),
            build.rectangle(PATCH_CENTRE, normal=[1, 0, 0], up=[0, 1, 0], width_m=side_m, material="square"),
        ],
        emitters=[
            build.rectangle(
                EMITTER_CENTRE,
                normal=EMITTER_NORMAL,
                up=UP,
                width_m=EMITTER_SIDE_M,
                spectrum={"type": "d65"},
                radiance_scale=10.0,
            )
        ],
    )


def vcz_coherence_lengths_um(side_m: float, receiver_x_m: float, nodes: int = 160) -> np.ndarray:
    """(ℓ₁, ℓ₂) of VCZ for the square as lit by the emitter and seen from the receiver (quadrature)."""
    grid = (np.arange(nodes) + 0.5) / nodes - 0.5
    y, z = np.meshgrid(PATCH_CENTRE[1] + side_m * grid, side_m * grid, indexing="ij")
    points = np.stack([np.full_like(y, PATCH_CENTRE[0]), y, z], axis=-1).reshape(-1, 3)
    emitter_grid = (np.arange(24) + 0.5) / 24 - 0.5
    u, v = np.meshgrid(EMITTER_SIDE_M * emitter_grid, EMITTER_SIDE_M * emitter_grid, indexing="ij")
    width_axis = np.cross(UP, EMITTER_NORMAL)
    emitter = (EMITTER_CENTRE + u[..., None] * width_axis + v[..., None] * UP).reshape(-1, 3)
    to_emitter = emitter[None] - points[:, None]
    distance2 = np.sum(to_emitter**2, axis=-1)
    cos_square = to_emitter[..., 0] / np.sqrt(distance2)
    cos_emitter = -(to_emitter @ EMITTER_NORMAL) / np.sqrt(distance2)
    irradiance = np.sum(np.clip(cos_square, 0, None) * np.clip(cos_emitter, 0, None) / distance2, axis=1)
    to_receiver = np.array([receiver_x_m, 0.0, 0.0]) - points
    distance = np.linalg.norm(to_receiver, axis=1)
    # L cos θ_r dω with dω = cos θ_square dA / r² (the square's normal is +x, the floor's +y).
    weight = irradiance * (to_receiver[:, 0] / distance) * (to_receiver[:, 1] / distance) / distance**2
    weight /= weight.sum()
    arrival = -to_receiver / distance[:, None]
    mean = weight @ arrival
    covariance = np.einsum("n,ni,nj->ij", weight, arrival, arrival) - np.outer(mean, mean)
    axis = mean / np.linalg.norm(mean)
    transverse = np.eye(3) - np.outer(axis, axis)
    eigenvalues = np.linalg.eigvalsh(transverse @ covariance @ transverse)[1:]
    return np.sort(1e6 / (K_PER_M * np.sqrt(eigenvalues)))[::-1]


def rendered_coherence_lengths_um(side_m: float, receiver_x_m: float, tmp_path: Path):
    """(ℓ₁, ℓ₂) of the pixel-mean M and their standard errors, and the mean r (m)."""
    out = tmp_path / f"a{side_m}_x{receiver_x_m}"
    render_scene(validate_scene(scene(side_m, receiver_x_m)), out, seed=3)
    channel = {
        name: values.astype(float).ravel() for name, values in read_exr(out / "image.exr").channels.items()
    }
    assert np.all(channel["coherence.weight"] > 0)
    m = np.stack(
        [
            channel["coherence.Mxx"],
            channel["coherence.Mxy"],
            channel["coherence.Mxy"],
            channel["coherence.Myy"],
        ],
        axis=-1,
    ).reshape(-1, 2, 2)
    eigenvalues, vectors = np.linalg.eigh(m.mean(axis=0))
    along = np.einsum("ai,nab,bi->ni", vectors, m, vectors)
    eigenvalue_se = along.std(axis=0, ddof=1) / math.sqrt(len(m))
    lengths = 1e6 / np.sqrt(eigenvalues)  # M already includes k² at 550 nm
    return lengths, 0.5 * lengths * eigenvalue_se / eigenvalues, float(channel["coherence.r_m"].mean())


@pytest.mark.parametrize(("side_m", "receiver_x_m"), [(0.2, 2.0), (0.4, 2.0), (0.4, 4.79)])
def test_light_from_a_diffuse_square_has_the_vcz_coherence_of_the_lit_square(
    side_m: float, receiver_x_m: float, tmp_path: Path
) -> None:
    lengths, standard_error, r_mean = rendered_coherence_lengths_um(side_m, receiver_x_m, tmp_path)
    expected = vcz_coherence_lengths_um(side_m, receiver_x_m)
    distance = float(np.linalg.norm(np.array([receiver_x_m, 0, 0]) - PATCH_CENTRE))
    assert r_mean == pytest.approx(distance, rel=0.01)
    tolerance = 4 * standard_error + 0.005 * expected
    assert np.all(np.abs(lengths - expected) <= tolerance), (lengths, expected, standard_error)


def test_vcz_reference_scales_as_distance_over_side() -> None:
    """The closed-form law ℓ ∝ d/a for the unforeshortened axis (the square's z edge, ⟂ the view plane):
    doubling a halves ℓ₂; doubling a and d together (receiver at 4.79 m: d = 5.38 m = 2 × 2.69 m) keeps
    it, up to the change of foreshortening and irradiance the quadrature includes (≤ 2 %). With the
    rendered test above this pins the renderer to ℓ ∝ d/a."""
    base = vcz_coherence_lengths_um(0.2, 2.0)
    assert vcz_coherence_lengths_um(0.4, 2.0)[1] == pytest.approx(base[1] / 2, rel=0.02)
    assert vcz_coherence_lengths_um(0.4, 4.79)[1] == pytest.approx(base[1], rel=0.02)
    # The closed form for a uniform square seen face-on, ℓ = d/(k·a/√12), to within the same 2 %.
    assert base[1] == pytest.approx(2.6937 / (K_PER_M * 0.2 / math.sqrt(12)) * 1e6, rel=0.02)
