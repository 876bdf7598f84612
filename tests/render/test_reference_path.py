"""``hg_path`` agrees with Mitsuba's built-in ``path`` integrator where coherence cannot matter.

On scenes made only of diffuse and perfectly specular materials the HG integrator must estimate the same
spectral radiance as ``path`` (issue 3, "How it is verified"). Both renders are unbiased estimates of the
same per-band image mean, so their difference has mean 0 and standard deviation √(SE_hg² + SE_path²) (the
renders are independent); we require |Δ| ≤ 3·√(SE_hg² + SE_path²) in every band. The seeds are fixed, so
the outcome is reproducible; for B bands of a correct renderer the chance that some band lies beyond 3σ is
about B·0.27% (2% for 8 bands). See ``tests.support.reference`` for the standard errors and the film.
Each test also asserts that its standard errors are small enough (≤ 3% of the mean) for the comparison to
be able to fail on a real bias of a few per cent.
"""

from __future__ import annotations

from pathlib import Path

from tests.support.reference import assert_agreement
from tests.support.render_scenes import mirror_room
from tests.support.scenes import example


def test_cornell_box_matches_path(tmp_path: Path) -> None:
    # 32×32 px × 512 spp = 524k samples: ≈1% SE per band of 8 (each band sees a sample's wavelength with
    # probability 1/2); path's 8 × 128 spp add less error, so hg_path's SE dominates the combined one.
    scene = example("cornell_box", width=32, height=32, spp=512, bands=8, max_depth=5)
    assert_agreement(scene, tmp_path, path_spp=128)


def test_mirror_room_matches_path(tmp_path: Path) -> None:
    # Paths through the perfect mirror (camera → mirror → light, floor → mirror → light caustics) are the
    # specular chains whose Θ/r bookkeeping hg_path adds; the radiance must not change.
    scene = mirror_room(size_px=32, spp=512, max_depth=5, bands=8)
    assert_agreement(scene, tmp_path, path_spp=128)


def test_mirror_room_with_glass_sphere_matches_path(tmp_path: Path) -> None:
    # Refraction through a smooth glass ball (n = 1.5: Fresnel choice, 1/η² radiance scaling, total
    # internal reflection) alongside the mirror, at Mitsuba's default depth 8.
    scene = mirror_room(size_px=32, spp=512, max_depth=8, bands=8, glass_sphere=True)
    assert_agreement(scene, tmp_path, path_spp=128)
