"""White furnaces (``furnace.py``): lossless materials return the walls' radiance, within max(1 %, 4 SE).

The 1 % floor covers what the estimator does not: four hero wavelengths per path over four bands, the
finite path depth (48 bounces; a glass ball loses < 0.04⁴⁸ to it) and, for thin films, that a reflected and
a transmitted path resolve their partial coherence against different walls (R(V_a) + T(V_b) = 1 holds
only on average; measured ≤ 0.3 %).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.integrator.furnace import box, furnace_ratio, furnace_scene, sphere

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

# Known defects of the kernels' hero-wavelength MIS (worker/render/bsdfs.py, integrator.py; not in the
# optics): the four wavelengths' pdfs are averaged per vertex while the hero is fixed per path, which is
# biased high when two or more vertices have wavelength-dependent lobes (measured +1.2 % ± 0.1 %, band
# edges +2.1 %, middle bands +0.1 %); and after a dispersive specular refraction (one wavelength left) the
# lobe's weight still divides by the four-wavelength mean pdf (+6 % ± 0.4 %). Strict: these fail until fixed.
HERO_MIS_DEFECT = "hero-wavelength MIS is per vertex, not per path (physics notes, issue 12 item D)"


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
KNOWN_BIASED = {"σ 0.2 µm, ℓc 20 µm (narrow lobe)", "dispersive (BK7), σ 0.1 µm, ℓc 2 µm"}


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


@pytest.mark.parametrize(
    "name",
    [
        pytest.param(name, marks=pytest.mark.xfail(strict=True, reason=HERO_MIS_DEFECT))
        if name in KNOWN_BIASED
        else name
        for name in ROUGH_GLASS
    ],
)
def test_rough_glass_ball_in_a_white_furnace_returns_one(name: str, tmp_path: Path) -> None:
    """Harvey–Shack renormalised over the propagating part (issue 12: σ 0.3 µm / ℓc 1 µm read 0.874)."""
    material = {"type": "rough_dielectric", "ior": 1.5, **ROUGH_GLASS[name]}
    scene = furnace_scene(material, sphere(), size_px=16, spp=256)
    assert_furnace(*furnace_ratio(scene, tmp_path))
