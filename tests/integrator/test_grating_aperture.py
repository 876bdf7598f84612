"""A grating's diffraction order seen through a lens: across the streak, the source convolved with the lens
cone and the lobe.

The DVD of ``tests.support.render_scenes.dvd_under_sphere`` (camera h = 0.3 m above, looking down; a sphere of
radius R = 1 cm 0.3 m from the centre, at the first order's incidence): the −1st order of each wavelength
leaves with β_x = sin θ_i − λ/Λ, a rainbow streak along the image's x (world +x); across it (world z, along
the grating's lines) the order is the mirror image of the source. A pixel at image coordinates
(t_x, t_z) = (tan φ, tan θ) sees the grating point p = h(t_x, 0, t_z) and leaves it along β_z ≈ −t_z cos φ;
the source's centre lies at β_z = −h t_z/s(x) seen from p (s: the distance from p to the sphere), so the
pixel takes the source's profile at the offset t_z (cos φ + h/s) — plus, for each ray of its lens cone
(focused on the grating: directions uniform on a disk of angular radius a/h around the pixel's), that ray's
direction offset, and the lobe's intrinsic width (Eq. 19/20 per lobe, docs/physics_interactions.md §4: what
a pinhole pixel collects from every direction of the source). Per column, in t_z:

    σ² = [(R/s)²/4 + (a/h)²/4 + (wλ/2π)²] / (cos φ + h/s)² + p²/12        (source, cone, lobe, pixel p),

and the whole streak's variance across is the column energies' weighted mean of them (the energies from the
render itself: they are radiometry, not coherence). The closed form holds for every mode count (``hg_path``'s
lobe has the source's variance; the modes shape it). ``rlt`` (the plane-wave ensemble: an intrinsic lobe
around each sampled point of the sphere) and ``hg_path`` (the lobe convolved with the sphere's coherence,
evaluated at the path's own pixel ray) must both give it at a pinhole and at lenses whose cone is smaller
than (0.5 cm), like (1 cm) and larger than (3 cm) the source's angular size, and the same energy (the lens
moves light within the streak).

Error model: the profile's variance from the image (columns summed, rows at their t_z), its Monte Carlo SE a
jackknife over 8 groups of columns (independent pixels). Tolerance 4 SE (combined for two estimates) plus
2 % of σ² for the closed form's approximations: small angles (t_z ≤ 0.08 over ±3σ: ≤ 0.7 %), λ = 550 nm in
the lobe's width for every column (w λ/2π is ≤ 7 % of σ, its band spread changes σ² by ≤ 0.5 %), the
sphere's z-extent taken from its centre's distance (≤ 0.5 %), and the field's tails (±0.27 ≥ 5σ).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from schemas import validate_scene
from tests.support import render_scenes as scenes
from tests.support.exr import read_channels, spectral_stack
from worker.render.chunks import render_scene

SOURCE_RADIUS_M = 0.01
APERTURES_M = (0.0, 0.005, 0.01, 0.03)
SIZE_PX = 64
FOV_DEG = 30.0
INTRINSIC_WIDTH_PER_UM = 0.05


def scene(aperture_radius_m: float, integrator: str) -> dict:
    data = scenes.dvd_under_sphere(SOURCE_RADIUS_M, spp=64)
    data["film"] |= {"width": SIZE_PX, "height": SIZE_PX, "integrator": integrator}
    data["camera"]["fov_deg"] = FOV_DEG
    if aperture_radius_m > 0.0:
        data["camera"]["aperture_radius_m"] = aperture_radius_m
    return data


def image_coordinates() -> np.ndarray:
    """tan of the angles of the pixel centres from the view axis, along either image axis."""
    return (2.0 * (np.arange(SIZE_PX) + 0.5) / SIZE_PX - 1.0) * math.tan(math.radians(FOV_DEG / 2.0))


def across_streak_moments(
    image: np.ndarray, groups: int = 8
) -> tuple[float, float, float, float, np.ndarray]:
    """(variance, its SE, energy, its SE, column energies) of the streak's profile across it, in t_z: rows
    weighted by their sums over every column and band; SEs by a jackknife over groups of columns."""
    rows = -image_coordinates()  # row 0 is the top of the image
    columns = image.sum(axis=-1)  # (rows, columns)

    def moments(selected: np.ndarray) -> tuple[float, float]:
        profile = selected.sum(axis=1)
        total = profile.sum()
        mean = profile @ rows / total
        return float(profile @ (rows - mean) ** 2 / total), float(total)

    variance, energy = moments(columns)
    group_of = np.arange(SIZE_PX) % groups
    jack = np.array([moments(columns[:, group_of != g]) for g in range(groups)])
    # leave-one-out energies are (groups − 1)/groups of the whole: compare them at full size
    jack[:, 1] *= groups / (groups - 1)
    errors = np.sqrt((groups - 1) / groups * np.sum((jack - jack.mean(axis=0)) ** 2, axis=0))
    return variance, float(errors[0]), energy, float(errors[1]), columns.sum(axis=0)


def closed_form_variance(aperture_radius_m: float, column_energies: np.ndarray) -> float:
    """The module docstring's σ², averaged over the columns with weights ``column_energies``."""
    height = scenes.GRATING_CAMERA_HEIGHT_M
    elevation = math.asin(scenes.GRATING_INCIDENCE_SINE)
    light_x = -scenes.GRATING_LIGHT_DISTANCE_M * math.sin(elevation)
    light_y = scenes.GRATING_LIGHT_DISTANCE_M * math.cos(elevation)
    t_x = image_coordinates()
    distance = np.hypot(height * t_x - light_x, light_y)  # grating point (h t_x, 0, 0) to the sphere's centre
    cos_phi = 1.0 / np.sqrt(1.0 + t_x**2)
    spread = (
        (SOURCE_RADIUS_M / distance) ** 2 / 4.0
        + (aperture_radius_m / height) ** 2 / 4.0
        + (INTRINSIC_WIDTH_PER_UM * 0.55 / (2.0 * math.pi)) ** 2
    )
    per_column = spread / (cos_phi + height / distance) ** 2
    pixel = 2.0 * math.tan(math.radians(FOV_DEG / 2.0)) / SIZE_PX
    return float(column_energies @ per_column / column_energies.sum()) + pixel**2 / 12.0


@pytest.fixture(scope="module")
def streaks(
    tmp_path_factory: pytest.TempPathFactory,
) -> dict[tuple[str, float], tuple[float, float, float, float, np.ndarray]]:
    root = tmp_path_factory.mktemp("grating")
    result = {}
    for aperture in APERTURES_M:
        for integrator in ("hg_path", "rlt"):
            out = root / f"{integrator}_{aperture}"
            render_scene(validate_scene(scene(aperture, integrator)), out, seed=5)
            result[integrator, aperture] = across_streak_moments(
                spectral_stack(read_channels(Path(out) / "image.exr"))[1]
            )
            variance, variance_error, energy, energy_error, columns = result[integrator, aperture]
            print(
                f"{integrator} {aperture}: σ² {variance:.3e} ± {variance_error:.1e} "
                f"(closed form {closed_form_variance(aperture, columns):.3e}), "
                f"energy {energy:.4g} ± {energy_error:.2g}"
            )
    return result


@pytest.mark.parametrize("aperture", APERTURES_M)
def test_the_order_is_the_source_convolved_with_the_lens_cone_and_the_lobe(
    streaks: dict, aperture: float
) -> None:
    for integrator in ("hg_path", "rlt"):
        variance, error, _, _, columns = streaks[integrator, aperture]
        expected = closed_form_variance(aperture, columns)
        assert abs(variance - expected) <= 4.0 * error + 0.02 * expected, (
            integrator,
            aperture,
            variance,
            error,
            expected,
        )


def test_the_lens_moves_the_order_s_light_without_changing_its_energy(streaks: dict) -> None:
    reference, reference_error = streaks["rlt", 0.0][2:4]
    for key, (_, _, energy, error, _) in streaks.items():
        assert abs(energy - reference) <= 4.0 * math.hypot(error, reference_error), (key, energy, reference)
