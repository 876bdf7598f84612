"""The coherence a pixel sees depends on the camera: a coated plane under a disk at four apertures.

Scene and closed form: ``tests.support.ensemble`` (a split plane, smooth and rough halves of one film, seen
at 45° from 0.3 m; a disk of angular radius α = 0.133 rad in the mirror direction). Lens radii 0 (a
pinhole), 1, 4 and 12 cm, focused on the plane: cones of angular radius 0.033, 0.133 and 0.4 rad, smaller
than, equal to and larger than the disk. For each, three renders: ``hg_path`` with the disk an emitter,
``rlt`` (the plane-wave ensemble) with the disk an emitter, and ``hg_path`` with the disk a uniformly lit
diffuse surface (a secondary source, the same light by van Cittert–Zernike). The fringe visibility V̂ of
each crop (``tests.support.fringes``) is compared with the closed form's.

What must hold (docs/physics_interactions.md §3, "What a pixel sees"):
* the smooth half passes one direction of the source per ray of the pixel's cone: at a pinhole the
  fringes keep their full visibility whatever the source, and the aperture washes them out as its cone
  covers more of the disk — hg_path, rlt and the lit disk all give the closed form's V̂;
* the rough half passes its lobe's width; rlt and the lit disk (paths sample that average) give the
  closed form's V̂, hg_path its closed-form combination of lobe and disk (``hgcore.optics.acceptance``),
  within that combination's error, bounded here by the same quadrature.

Error model. V̂'s Monte Carlo standard error is a jackknife over 8 groups of each crop's pixels
(``ensemble.rendered_visibility``): 0.002–0.02 at 192–384 spp. Tolerances: 4 SE (combined for two renders)
+ the closed form's quadrature error (``ensemble.QUADRATURE_TOLERANCE``, 0.008), and for hg_path on the rough
half + ``ROUGH_MODEL_TOLERANCE``: the largest difference between the model's visibility and the exact
ensemble over the film's wavelengths at the crop's centre (computed below with the same quadrature: 0.05–0.07
at a pinhole, where the lobe and the disk are of a size and the 0th mode's Gaussian shape errs most).

Before this change (main at 8cb6173) the pinhole's smooth crop read V̂ = 0.52 for the emitter (the whole
disk's Σ⊥: Eq. 18's washout) against 0.98 for the lit disk and 0.99 closed form (the smooth and invariance
tests fail there), its rough crop 0.53 (exact 0.56: within the rough test's tolerance), and the aperture
did not exist (the scene is refused).
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import pytest

from schemas import validate_scene
from tests.support import ensemble
from tests.support.exr import read_channels, spectral_stack
from worker.render.chunks import render_scene

APERTURES_M = (0.0, 0.01, 0.04, 0.12)
VARIANTS = {  # name: (lit disk, integrator, spp)
    "emitter": (False, "hg_path", 192),
    "rlt": (False, "rlt", 192),
    "lit": (True, "hg_path", 384),
}


@pytest.fixture(scope="module")
def visibilities(
    tmp_path_factory: pytest.TempPathFactory,
) -> dict[tuple[str, float, str], tuple[float, float]]:
    """(V̂, SE) per (variant, aperture, half) of the renders, and the closed form's under ("exact", …)."""
    root = tmp_path_factory.mktemp("detected")
    result = {}
    for aperture in APERTURES_M:
        for name, (lit, integrator, spp) in VARIANTS.items():
            out = root / f"{name}_{aperture}"
            render_scene(
                validate_scene(ensemble.scene(aperture, lit=lit, integrator=integrator, spp=spp)), out, seed=7
            )
            bands = spectral_stack(read_channels(Path(out) / "image.exr"))[1]
            result[name, aperture, "smooth"] = ensemble.rendered_visibility(bands, ensemble.SMOOTH_ROWS)
            result[name, aperture, "rough"] = ensemble.rendered_visibility(bands, ensemble.ROUGH_ROWS)
        result["exact", aperture, "smooth"] = (
            ensemble.visibility(ensemble.smooth_spectrum(aperture)).visibility,
            0.0,
        )
        result["exact", aperture, "rough"] = (
            ensemble.visibility(ensemble.rough_spectrum(aperture)).visibility,
            0.0,
        )
    for key, value in sorted(result.items(), key=lambda item: (item[0][1], item[0][2], item[0][0])):
        print(key, f"V̂ = {value[0]:.3f} ± {value[1]:.3f}")
    return result


def within(measured: tuple[float, float], expected: tuple[float, float], extra: float) -> bool:
    return abs(measured[0] - expected[0]) <= 4.0 * math.hypot(measured[1], expected[1]) + extra


@pytest.mark.parametrize("aperture", APERTURES_M)
def test_a_smooth_film_shows_the_fringes_of_the_source_directions_its_cone_reflects(
    visibilities: dict, aperture: float
) -> None:
    """The visibility-vs-aperture curve of the smooth half: full at a pinhole (every ray meets one point of
    the disk), falling as the lens cone covers more of it, down to the whole disk's washout; rlt, the
    emitter and the lit disk alike."""
    exact = visibilities["exact", aperture, "smooth"]
    for name in VARIANTS:
        measured = visibilities[name, aperture, "smooth"]
        assert within(measured, exact, ensemble.QUADRATURE_TOLERANCE), (name, aperture, measured, exact)


def test_the_aperture_washes_a_smooth_film_s_fringes_out() -> None:
    """The closed forms themselves: a pinhole keeps the fringes (V̂ > 0.95 over the crop's 2° of incidence),
    the widest lens washes them out to the disk's own visibility (the paper's Eq. 18), so the curve spans
    far more than the tolerances."""
    curve = [ensemble.visibility(ensemble.smooth_spectrum(a)).visibility for a in APERTURES_M]
    assert curve[0] > 0.95 and curve[-1] < 0.55
    assert all(later < earlier for earlier, later in itertools.pairwise(curve))


@pytest.mark.parametrize("aperture", APERTURES_M)
def test_a_rough_film_shows_the_source_directions_its_lobe_passes(
    visibilities: dict, aperture: float
) -> None:
    """rlt and the lit disk average over the lobe ∩ disk by their paths: the closed form; hg_path combines
    the lobe and the disk in closed form: within that combination's error."""
    exact = visibilities["exact", aperture, "rough"]
    for name in ("rlt", "lit"):
        measured = visibilities[name, aperture, "rough"]
        assert within(measured, exact, ensemble.QUADRATURE_TOLERANCE), (name, aperture, measured, exact)
    measured = visibilities["emitter", aperture, "rough"]
    tolerance = ensemble.QUADRATURE_TOLERANCE + ensemble.rough_model_tolerance()
    assert within(measured, exact, tolerance), (aperture, measured, exact, tolerance)


@pytest.mark.parametrize("aperture", APERTURES_M)
def test_an_emitter_and_an_equally_lit_diffuse_disk_give_the_same_fringes(
    visibilities: dict, aperture: float
) -> None:
    """Van Cittert–Zernike: the same light, the same fringe amplitude, at every aperture (the rough half
    within the closed-form combination's error, the emitter's lobe being combined analytically)."""
    for half, extra in (("smooth", 0.0), ("rough", ensemble.rough_model_tolerance())):
        emitter, lit = visibilities["emitter", aperture, half], visibilities["lit", aperture, half]
        assert within(emitter, lit, extra), (half, aperture, emitter, lit)
