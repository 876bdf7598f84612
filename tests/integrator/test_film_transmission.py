"""Light transmitted by a thin film on glass: T(V) = 1 − R(V), with the visibility of the light a pixel sees.

The camera looks at a coated glass surface at 45°; below it, inside the glass, an emitting sphere sits on
the refracted ray at r = 0.5 m. Every camera path that refracts hits the sphere directly, so the pixel is
L_e·T/n_s² (radiance is divided by n² leaving the denser medium). The camera is a pinhole and the film's
transmission specular: each pixel receives the plane wave of one point of the sphere, refracted at one
angle, so T is the film's *coherent* transmittance there whatever the sphere's size (V_d = 1;
docs/physics_interactions.md §3, "What a pixel sees") — a small sphere (ℓ ≫ the shear) and a large one
(the paper's Eq. 18 would give V₁ ≈ 0.27 at 550 nm: the whole sphere's Σ⊥ at the film shear) give the same
image. The reference evaluates T(V = 1) = 1 − R of the every-beam sum with ``hgcore.optics`` per wavelength
and averages it over each band (Simpson, 2 nm steps); the second test checks that the paper's partially
coherent T(V₁) differs from it by far more than the tolerance, so the renders tell the two apart.

Noise: the only random choice is reflect (probability R ≈ 0.15) or refract; a refracted path carries
T/(1 − R_hero) per wavelength. 4 pixels × 1024 spp over 16 bands give a standard error ≈ 0.3 % of a
band value; the tolerance is 5 SE from the pixels' scatter plus 0.5 % for the pixel footprint (the view
angle varies by ±0.05° and r by ±0.2 mm).
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest

from hgcore.artifacts.exr import read_exr
from hgcore.optics.array_ops import NUMPY
from hgcore.optics.complex_pair import ComplexPair
from hgcore.optics.thin_film import (
    combine_reflectance_terms,
    film_reflectance_terms,
    gaussian_visibilities,
    transmission_terms,
)
from schemas import build, validate_scene
from tests.integrator.scenes import coated_plane
from worker.render.chunks import render_scene

THICKNESS_M = 1.0e-6
FILM_IOR = 2.1
SUBSTRATE_IOR = 1.5
BEAMS = 4
ANGLE_DEG = 45.0
DISTANCE_M = 0.5
SIN_T = math.sin(math.radians(ANGLE_DEG)) / SUBSTRATE_IOR
COS_T = math.sqrt(1.0 - SIN_T**2)
# |s⊥| = 2τ tan θ_f cos θ_s: the film shear across the beam arriving from the substrate,
# sin θ_f = sin 45°/n_f
SHEAR_TRANSVERSE_M = (
    2 * THICKNESS_M * math.tan(math.asin(math.sin(math.radians(ANGLE_DEG)) / FILM_IOR)) * COS_T
)


def scene(sphere_radius_m: float) -> dict:
    view = (math.sin(math.radians(ANGLE_DEG)), 0.0, math.cos(math.radians(ANGLE_DEG)))
    centre = (-DISTANCE_M * SIN_T, 0.0, -DISTANCE_M * COS_T)
    return coated_plane(
        "transmission through a coated surface",
        view=view,
        film=build.film(2, bands=16, spp=1024, max_depth=3),
        coating={
            "film_thickness_um": THICKNESS_M * 1e6,
            "film_ior": FILM_IOR,
            "substrate": {"ior": SUBSTRATE_IOR},
            "beams": BEAMS,
        },
        emitter=build.sphere(
            centre, sphere_radius_m, spectrum={"type": "constant", "value": 1.0}, radiance_scale=1.0
        ),
        fov_deg=0.1,
    )


def expected_band_values(sphere_radius_m: float | None, edges_nm: np.ndarray) -> np.ndarray:
    """Band means of L_e·T(V)/n_s² with V_d = V₁^{d²} of a sphere of radius ``sphere_radius_m`` at r (the
    paper's Eq. 18: V₁ = exp(−½ (k/r)² |s⊥|² R²/4), 0th mode), or V ≡ 1 (``None``: what a pinhole sees)."""
    values = []
    for low, high in itertools.pairwise(edges_nm):
        intervals = 2 * math.ceil((high - low) / 4.0)  # even (Simpson), ≤ 2 nm steps
        wavelengths_m = np.linspace(low, high, intervals + 1) * 1e-9
        cos_i = np.full_like(wavelengths_m, math.cos(math.radians(ANGLE_DEG)))
        substrate = ComplexPair(np.full_like(wavelengths_m, SUBSTRATE_IOR), np.zeros_like(wavelengths_m))
        terms = film_reflectance_terms(
            cos_i, wavelengths_m, THICKNESS_M, FILM_IOR, substrate, 1.0, BEAMS, NUMPY
        )
        k = 2 * math.pi / wavelengths_m
        radius_m = 0.0 if sphere_radius_m is None else sphere_radius_m
        first = np.exp(-0.5 * (k / DISTANCE_M) ** 2 * SHEAR_TRANSVERSE_M**2 * radius_m**2 / 4)
        visibilities = gaussian_visibilities(first, BEAMS - 1, NUMPY)
        transmittance = combine_reflectance_terms(transmission_terms(terms), visibilities)
        radiance = transmittance / SUBSTRATE_IOR**2
        step = wavelengths_m[1] - wavelengths_m[0]
        simpson = np.ones_like(radiance)
        simpson[1:-1:2], simpson[2:-1:2] = 4.0, 2.0
        values.append(np.sum(simpson * radiance) * step / 3.0 / (wavelengths_m[-1] - wavelengths_m[0]))
    return np.array(values)


def rendered_band_values(sphere_radius_m: float, tmp_path: Path) -> tuple[np.ndarray, np.ndarray, list]:
    out = tmp_path / f"R{sphere_radius_m}"
    render_scene(validate_scene(scene(sphere_radius_m)), out, seed=5)
    image = read_exr(out / "image.exr")
    bands = [name for name in image.channels if name.startswith("S0.")]
    per_pixel = np.stack([image.channels[name].astype(float).ravel() for name in bands])
    return per_pixel.mean(axis=1), per_pixel.std(axis=1, ddof=1) / math.sqrt(per_pixel.shape[1]), bands


@pytest.mark.parametrize("sphere_radius_m", [0.005, 0.3])
def test_transmitted_light_is_the_coherent_transmittance_at_a_pinhole(
    sphere_radius_m: float, tmp_path: Path
) -> None:
    values, error, bands = rendered_band_values(sphere_radius_m, tmp_path)
    centres = np.array([float(name[3:-2].replace(",", ".")) for name in bands])
    width = centres[1] - centres[0]
    edges = np.concatenate([centres - width / 2, [centres[-1] + width / 2]])
    expected = expected_band_values(None, edges)
    assert np.all(np.abs(values - expected) <= 5 * error + 0.005 * expected), (values, expected, error)


def test_the_paper_s_washout_differs_from_what_a_pinhole_sees() -> None:
    """The large sphere's Eq. 18 reference (its whole Σ⊥ at the film shear) differs from the coherent one
    by far more than the test's tolerance: the render above tells the two apart (it failed before the
    detector was taken into account, reading the partially coherent values)."""
    edges = np.linspace(380.0, 780.0, 17)
    coherent, washed_out = expected_band_values(None, edges), expected_band_values(0.3, edges)
    assert np.max(np.abs(coherent - washed_out) / coherent) > 0.05  # ≈ 7 %, vs a tolerance of ≈ 2 %
