"""White furnaces (``furnace.py``): lossless materials return the walls' radiance, within max(1 %, 4 SE).

The 1 % floor covers what the estimator does not: four hero wavelengths per path over four bands, the
finite path depth (48 bounces; a glass ball loses < 0.04⁴⁸ to it) and, for thin films, that a reflected and
a transmitted path resolve their partial coherence against different walls (R(V_a) + T(V_b) = 1 holds
only on average; measured ≤ 0.3 %).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.integrator.furnace import box, furnace_band_ratios, furnace_ratio, furnace_scene, sphere

COATING = {"type": "thin_film", "film_thickness_um": 0.4, "film_ior": 2.1, "substrate": {"ior": 1.5}}

LOSSLESS = {
    "white diffuse": {"type": "diffuse", "reflectance": 1.0},
    "perfect mirror": {"type": "mirror", "conductor": "perfect"},
    "glass": {"type": "dielectric", "ior": 1.5},
    "dispersive glass": {"type": "dielectric", "ior": "bk7"},
    "coated glass (smooth film)": {**COATING, "roughness_rms_um": 1e-6},
    "coated glass (rough film)": {**COATING, "roughness_rms_um": 0.05, "correlation_length_um": 5.0},
    "coated glass, 2 beams": {**COATING, "roughness_rms_um": 1e-6, "beams": 2},
    "coated glass (ABC rough film)": {
        **COATING,
        "roughness_rms_um": 0.05,
        "correlation_length_um": 5.0,
        "psd": "abc",
    },
    "coated dispersive glass": {
        **COATING,
        "film_ior": 1.38,
        "substrate": {"ior": "bk7"},
        "roughness_rms_um": 1e-6,
    },
}

ROUGH_GLASS = {
    # σ/λ up to 0.5 over the visible range (σ 0.19 µm at 380 nm), correlation lengths down to 1 µm
    "σ 0.1 µm, ℓc 2 µm": {"roughness_rms_um": 0.1, "correlation_length_um": 2.0},
    "σ 0.19 µm, ℓc 1 µm": {"roughness_rms_um": 0.19, "correlation_length_um": 1.0},
    "σ 0.05 µm, ℓc 20 µm": {"roughness_rms_um": 0.05, "correlation_length_um": 20.0},
    "ABC σ 0.1 µm, ℓc 1 µm": {"roughness_rms_um": 0.1, "correlation_length_um": 1.0, "psd": "abc"},
    "σ 0.2 µm, ℓc 20 µm (narrow lobe)": {"roughness_rms_um": 0.2, "correlation_length_um": 20.0},
    "dispersive (BK7), σ 0.1 µm, ℓc 2 µm": {
        "roughness_rms_um": 0.1,
        "correlation_length_um": 2.0,
        "ior": "bk7",
    },
}


def assert_furnace(ratio: float, error: float) -> None:
    assert abs(ratio - 1.0) <= max(0.01, 4.0 * error), (ratio, error)


@pytest.mark.parametrize("name", list(LOSSLESS))
def test_lossless_ball_in_a_white_furnace_returns_one(name: str, tmp_path: Path) -> None:
    assert_furnace(*furnace_ratio(furnace_scene(LOSSLESS[name], sphere()), tmp_path))


def test_coated_glass_slab_in_a_white_furnace_returns_one(tmp_path: Path) -> None:
    """A coated slab (a closed box mesh): light crosses two coated faces, or is trapped and bounces."""
    slab = box((0.6, 0.6, 0.1))
    material = {**COATING, "roughness_rms_um": 1e-6}
    assert_furnace(*furnace_ratio(furnace_scene(material, slab), tmp_path))


@pytest.mark.parametrize("name", list(ROUGH_GLASS))
def test_rough_glass_ball_in_a_white_furnace_returns_one(name: str, tmp_path: Path) -> None:
    """Harvey–Shack renormalised over the propagating part (issue 12: σ 0.3 µm / ℓc 1 µm read 0.874).

    The narrow lobe and the dispersive glass have wavelength-dependent lobes at two or more vertices of a
    path: they read 1.0116 ± 0.0010 and 1.062 ± 0.004 with hero-wavelength MIS per vertex and need it per
    path (docs/integrator.md)."""
    material = {"type": "rough_dielectric", "ior": 1.5, **ROUGH_GLASS[name]}
    scene = furnace_scene(material, sphere(), size_px=16, spp=256)
    assert_furnace(*furnace_ratio(scene, tmp_path))


def test_wide_rough_lobe_returns_one_once_paths_are_deep_enough(tmp_path: Path) -> None:
    """Issue 26's widest set, σ 0.3 µm / ℓc 1 µm (σ/λ 0.55 at 550 nm): 0.963 ± 0.003 at the default
    max_depth 8, where light trapped by total internal reflection is cut off, and 1 within max(1 %, 4 SE)
    at 64 (measured 1.002 ± 0.010; docs/physics_interactions.md)."""
    material = {"type": "rough_dielectric", "ior": 1.5, "roughness_rms_um": 0.3, "correlation_length_um": 1.0}
    scene = furnace_scene(material, sphere(), size_px=24, spp=512, max_depth=64)
    assert_furnace(*furnace_ratio(scene, tmp_path))


@pytest.mark.parametrize("name", ["σ 0.2 µm, ℓc 20 µm (narrow lobe)", "dispersive (BK7), σ 0.1 µm, ℓc 2 µm"])
def test_rough_glass_ball_returns_one_in_every_band(name: str, tmp_path: Path) -> None:
    """Wavelength-dependent lobes at several vertices of a path: with hero-wavelength MIS per vertex the
    spectrum's ends read high (narrow lobe 1.021 ± 0.005 and 1.021 ± 0.004 in the first and last band,
    dispersive glass 1.11 and 1.12) while the middle bands were right; each band must return 1 within
    max(1 %, 4 SE)."""
    material = {"type": "rough_dielectric", "ior": 1.5, **ROUGH_GLASS[name]}
    scene = furnace_scene(material, sphere(), size_px=16, spp=256)
    for band, (ratio, error) in enumerate(furnace_band_ratios(scene, tmp_path)):
        assert abs(ratio - 1.0) <= max(0.01, 4.0 * error), (band, ratio, error)
