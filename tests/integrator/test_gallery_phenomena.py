"""The gallery scenes show their phenomena: numbers measured in low-resolution renders of the examples.

Each test compares a measured quantity with an independent closed form or a physical ordering:
the grating equation's wavelength ordering along the DVD's first-order streak; the uniform-strip and
uniform-disk van Cittert–Zernike coherence lengths ℓ = r·√12/(k·L) and ℓ = 2r/(k·a) on the coated
surfaces (with r from the scene's geometry, through the mirror's virtual source for Fig. 8); and the 1- vs
16-mode ΔE₀₀ of Fig. 9 against the just-noticeable difference. The coherence diagnostics are
luminance-weighted per-pixel means whose Monte Carlo scatter is far below the tolerances (medians over
tens of pixels); the tolerances cover the part of a pixel's light that comes from the backdrop (a
secondary source of much shorter coherence) instead.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from hgcore.artifacts.exr import read_exr
from hgcore.optics.array_ops import NUMPY
from hgcore.optics.thin_film import film_shear
from schemas import validate_scene
from tests.support.scenes import example
from worker.render.chunks import render_scene

REC709 = np.array([0.2126, 0.7152, 0.0722])


@dataclass
class Render:
    bands: np.ndarray  # (H, W, B) spectral radiance
    wavelengths_nm: np.ndarray
    luminance: np.ndarray  # (H, W)
    normal: np.ndarray  # (H, W, 3) world normal of the first hit
    depth_m: np.ndarray  # (H, W) distance to the first hit


def render(name: str, tmp_path: Path, size_px: int, spp: int, scene: dict | None = None) -> Render:
    """Render the example ``name`` (or ``scene``) at size_px² and spp into ``tmp_path / name``."""
    out = tmp_path / name
    if scene is None:
        scene = example(name, width=size_px, height=size_px, spp=spp)
    render_scene(validate_scene(scene), out, spp=spp)
    image = read_exr(out / "image.exr")
    bands = image.band_names()
    return Render(
        bands=image.stack(bands).astype(np.float64),
        wavelengths_nm=np.array([w for w, _ in image.spectral_channels()]),
        luminance=(image.rgb @ REC709).astype(np.float64),
        normal=image.stack([f"normal.{a}" for a in "XYZ"]),
        depth_m=image.channels["depth"].astype(np.float64),
    )


# --- Fig. 1(f): DVDs -----------------------------------------------------------------------------


def first_order_rows(image: Render) -> tuple[np.ndarray, np.ndarray]:
    """Per image row of the near half (where the framing puts the first order, docs/gallery.md): the
    luminance-weighted mean wavelength of the streak's pixels (those above 10 % of the half's peak) and
    the streak's luminance-weighted RMS width in pixels (over the central quarter of the columns)."""
    height, width = image.luminance.shape
    near = slice(height // 2 + height // 16, height)
    luminance, bands = image.luminance[near], image.bands[near]
    streak = luminance > 0.1 * luminance.max()
    rows = [r for r in range(streak.shape[0]) if streak[r].any()]
    energy = np.array([bands[r][streak[r]].sum(axis=0) for r in rows])
    columns = np.arange(width // 2 - width // 8, width // 2 + width // 8)
    weights = luminance[rows][:, columns]
    centre = (weights @ columns) / weights.sum(axis=1)
    spread = (weights * (columns[None, :] - centre[:, None]) ** 2).sum(axis=1) / weights.sum(axis=1)
    return energy @ image.wavelengths_nm / energy.sum(axis=1), np.sqrt(spread)


@pytest.mark.slow
def test_dvd_first_order_is_a_rainbow_widened_by_the_larger_source(tmp_path: Path) -> None:
    """Along the first-order streak the grating equation sin θ_o + sin θ_i = λ/d maps the falling angle
    from the disc centre towards the rim onto falling wavelengths: red by the hole, violet at the rim.
    The 6× larger source of the same power draws a rainbow from each of its points: a wider streak."""
    widths = {}
    for kind in ("small", "large"):
        image = render(f"fig1f_dvd_{kind}_source", tmp_path, 128, 16)
        mean_wavelength_nm, width_px = first_order_rows(image)
        assert len(mean_wavelength_nm) >= 6, kind
        # One band is 25 nm: the hue falls by over three bands along the streak, monotone within a band.
        assert mean_wavelength_nm[0] - mean_wavelength_nm.min() > 75.0, kind
        assert np.all(np.diff(mean_wavelength_nm) < 25.0), kind
        widths[kind] = float(np.mean(width_px))
    assert widths["large"] > 1.5 * widths["small"]


# --- Fig. 7 / Fig. 8: the coherence the coated surfaces receive ----------------------------------

K_550_PER_M = 2.0 * math.pi / 550e-9


def brightest_material_pixels(image: Render, albedo: np.ndarray, threshold: float) -> np.ndarray:
    """Pixels above ``threshold`` × the 99th luminance percentile among those whose first hit has the
    albedo of the brightest pixel (the lit coated object)."""
    brightest = np.unravel_index(np.argmax(image.luminance), image.luminance.shape)
    same_material = np.all(np.abs(albedo - albedo[brightest]) < 0.1, axis=-1)
    return same_material & (image.luminance > threshold * np.percentile(image.luminance[same_material], 99))


def coherence(out: Path) -> dict[str, np.ndarray]:
    image = read_exr(out / "image.exr")
    channels = {k: image.channels[f"coherence.{k}"] for k in ("l1_um", "l2_um", "r_m", "anisotropy")}
    channels["albedo"] = image.stack([f"albedo.{c}" for c in "RGB"])
    return channels


#: CIELAB distance of a just-noticeable colour difference (Sharma 2003, "Digital Color Imaging Handbook").
LAB_JND = 2.3


def highlight_chromaticity(out: Path, bin_px: int, floor: float) -> tuple[np.ndarray, np.ndarray]:
    """(a*, b*) of each bin_px² bin of the lit coated shell, and the bins' mask over the binned grid.

    Bins wholly on the shell — the pixels whose albedo AOV exceeds 0.3: silver's is ≈ 0.9 (its per-pixel
    value scatters with the sampled wavelengths, 0.6–1.3), the backdrop's 0.08 — whose luminance exceeds
    ``floor`` × the 99th percentile of those bins. Each bin's XYZ is scaled to Y = ½ (L* 76) before CIELAB
    (D65 white): only its chromaticity counts, not where it sits in the highlight's fall-off — a colour
    band, not a shading."""
    from hgcore.colour import linear_srgb_to_xyz, xyz_to_lab

    image = read_exr(out / "image.exr")
    rgb = image.rgb.astype(np.float64)
    albedo = image.stack([f"albedo.{c}" for c in "RGB"])
    luminance = rgb @ REC709
    material = albedo.mean(axis=-1) > 0.3
    rows, columns = (size // bin_px for size in luminance.shape)

    def binned(x: np.ndarray) -> np.ndarray:
        x = x[: rows * bin_px, : columns * bin_px]
        return x.reshape(rows, bin_px, columns, bin_px, *x.shape[2:]).mean(axis=(1, 3))

    whole = binned(material.astype(np.float64)) == 1.0
    rgb_bins = binned(rgb)
    bin_luminance = rgb_bins @ REC709
    lit = whole & (bin_luminance > floor * np.percentile(bin_luminance[whole], 99))
    xyz = linear_srgb_to_xyz(rgb_bins)
    xyz = 0.5 * xyz / np.maximum(xyz[..., 1:2], 1e-30)
    return xyz_to_lab(xyz, linear_srgb_to_xyz(np.ones(3)))[..., 1:], lit


def chromatic_spread(scene: dict, tmp_path: Path, tag: str) -> tuple[float, float]:
    """(spread, standard error): the RMS CIELAB (a*, b*) distance of the lit bins' chromaticities from
    their mean with the Monte Carlo noise taken out, from two renders of ``scene`` with different seeds.

    With A, B the two renders' bin chromaticities and s² a bin's noise variance in one, E|A − B|² = 2s² and
    their mean M carries s²/2, so each bin contributes d = |M − ⟨M⟩|² − |A − B|²/4 with E d = its true
    squared distance: spread² = ⟨d⟩. The bins' noise is independent (disjoint pixels), so ⟨d⟩'s standard
    error is std(d)/√N and the spread's, by the delta method, that over 2·spread."""
    chromaticities = []
    for seed in (1, 2):
        out = tmp_path / f"{tag}_{seed}"
        render_scene(validate_scene(scene), out, seed=seed)
        chromaticities.append(highlight_chromaticity(out, bin_px=2, floor=0.02))
    (a, lit_a), (b, lit_b) = chromaticities
    lit = lit_a & lit_b
    assert lit.sum() >= 30, tag
    mean = 0.5 * (a[lit] + b[lit])
    d = np.sum((mean - mean.mean(axis=0)) ** 2, axis=-1) - np.sum((a[lit] - b[lit]) ** 2, axis=-1) / 4.0
    spread = math.sqrt(max(float(d.mean()), 1e-12))
    return spread, float(d.std(ddof=1) / math.sqrt(d.size)) / (2.0 * spread)


def bare_silver(scene: dict) -> dict:
    """``scene`` with the coated shell replaced by rough silver of the same roughness: no film."""
    film = scene["materials"]["coated_silver"]
    keys = ("roughness_rms_um", "correlation_length_um", "psd", "psd_exponent")
    bare = {"type": "rough_conductor", "conductor": "Ag", **{key: film[key] for key in keys}}
    return {**scene, "materials": {**scene["materials"], "coated_silver": bare}}


#: How many times bare silver's chromaticity spread the coated shell's must exceed under the sphere:
#: "clearly visible" interference colours, not a tint (measured 128², 128 spp: see the test's print).
VIVID_FACTOR = 3.0


@pytest.mark.slow
def test_sphere_source_shows_the_film_colours_across_the_highlight(tmp_path: Path) -> None:
    """Fig. 7 (left): the film's colour follows its phase 2 n_f τ cos θ_t, and θ_t changes across the rough
    highlight, so the coated shell's lit part changes hue from place to place; the same shell in bare rough
    silver (same roughness, same light, no film) shows the lobe's own shading colour only. The coating
    absorbs (κ_f 0.12, docs/physics_interactions.md §3), so its fringes are deep and the colours vivid, not
    the pastel of a clear film on silver (spread 3.9 ± 0.1 vs bare 2.2 ± 0.2 with the former n 2.4 clear
    film). Asserted: the coated shell's chromaticity spread is above the just-noticeable difference, and
    more than ``VIVID_FACTOR`` × the bare shell's, each by more than 4 standard errors (Monte Carlo, from a
    second seed: ``chromatic_spread``)."""
    scene = example("fig7_thin_film_sphere_light", width=128, height=128, spp=128)
    coated, coated_error = chromatic_spread(scene, tmp_path, "coated")
    silver, silver_error = chromatic_spread(bare_silver(scene), tmp_path, "bare")
    print(f"spread: coated {coated:.2f} ± {coated_error:.2f}, bare silver {silver:.2f} ± {silver_error:.2f}")

    assert coated > LAB_JND + 4.0 * coated_error
    assert coated - VIVID_FACTOR * silver > 4.0 * math.hypot(coated_error, VIVID_FACTOR * silver_error)


def shear_along_tube_m(scene: dict, normal_x: float) -> float:
    """|s⊥·x̂| (m): the film shear's component along the tube (x) and transverse to the incident light, at
    the top of the coated shell for a normal that bisects the directions to the light and to the camera
    (the highlight's) tilted to ``normal_x`` along the tube."""
    shell = next(shape for shape in scene["shapes"] if shape["material"] == "coated_silver")
    film = scene["materials"]["coated_silver"]
    (tube,) = scene["emitters"]
    top = np.asarray(shell["center_m"]) + np.array([0.0, shell["semi_axes_m"][1], 0.0])
    light = 0.5 * (np.asarray(tube["p0_m"]) + np.asarray(tube["p1_m"]))

    def unit(v: np.ndarray) -> np.ndarray:
        return v / np.linalg.norm(v)

    to_light = unit(light - top)
    half = unit(to_light + unit(np.asarray(scene["camera"]["origin_m"]) - top))
    normal = np.array([normal_x, *(math.sqrt(1.0 - normal_x**2) * unit(half[1:]))])
    incident = -to_light
    shear = np.array(
        film_shear(normal, incident, film["film_thickness_um"] * 1e-6, film["film_ior"], 1.0, NUMPY)
    )
    transverse = shear - np.dot(shear, incident) * incident
    return abs(float(transverse[0]))


@pytest.mark.slow
def test_cylinder_source_keeps_the_film_colours_where_the_paper_fades_them(
    tmp_path: Path,
) -> None:
    """Fig. 7 (right) at a pinhole: the film's colour survives under the tube on the crest *and* the flanks.

    The paper (Eq. 18 with the whole source's Σ⊥) fades the colours where the normal tilts along the tube:
    there the film shear lies along the axis, across which the tube's coherence ℓ₂ (measured in the EXR) is
    shorter than the shear. But a pixel receives only the tube directions its lobe passes
    (docs/physics_interactions.md §3, "What a pixel sees"): this coating's K-correlation lobe (exponent 1.2,
    ℓc 0.5 µm, restricted to the propagating directions: ±0.34 rad at 550 nm) passes a fraction of the
    ±1.2 rad tube, over which the light is coherent far beyond the film's 0.13 µm shear — the plane-wave
    ensemble (``rlt``) keeps the fringes there as well (V̂ 0.74 on the leaning normals of the paper-test
    sphere, docs/physics_interactions.md). Showing the fading needs a film whose shear exceeds the coherence
    of what its lobe passes (a thicker, lower-index coating).

    Measure: per 2×2 bin of the lit shell, the CIELAB (a*, b*) distance between the coated render and bare
    rough silver rendered with the same seed (same paths, so the lobe's colour and most of the noise
    cancel): the film's own colour, under the tube over under the sphere. Asserted, each by 4 standard
    errors of the bins: the crest (|n_x| < 0.15) keeps its colour (ratio ≥ V(0.15) of the paper's reading,
    V = exp(−½ (s⊥·x̂/ℓ₂)²)), and so do the flanks (|n_x| ≥ 0.3), whose ratio the paper's reading puts below
    V(0.3) and which now stays above it."""
    size_px, bin_px = 96, 2
    departures = {}
    for kind in ("sphere", "cylinder"):
        name = f"fig7_thin_film_{kind}_light"
        scene = example(name, width=size_px, height=size_px, spp=64)
        chromaticity = {}
        for tag, variant in (("coated", scene), ("bare", bare_silver(scene))):
            out = tmp_path / f"{kind}_{tag}"
            render_scene(validate_scene(variant), out, seed=3)
            chromaticity[tag] = highlight_chromaticity(out, bin_px=bin_px, floor=0.02)
        (coated, lit_coated), (bare, lit_bare) = chromaticity["coated"], chromaticity["bare"]
        departures[kind] = (np.linalg.norm(coated - bare, axis=-1), lit_coated & lit_bare)
    # The camera and the shell are the same in both scenes: |n_x| per bin and ℓ₂ from the tube's render.
    image = read_exr(tmp_path / "cylinder_coated" / "image.exr")
    bins_per_side = size_px // bin_px
    nx = (
        np.abs(image.channels["normal.X"])
        .reshape(bins_per_side, bin_px, bins_per_side, bin_px)
        .mean(axis=(1, 3))
    )
    luminance = image.rgb @ REC709
    shell = image.stack([f"albedo.{c}" for c in "RGB"]).mean(axis=-1) > 0.3
    lit_px = shell & (luminance > 0.05 * np.percentile(luminance[shell], 99))
    l2_m = float(np.median(image.channels["coherence.l2_um"][lit_px])) * 1e-6

    def visibility(normal_x: float) -> float:
        return math.exp(-0.5 * (shear_along_tube_m(scene, normal_x) / l2_m) ** 2)

    lit = departures["sphere"][1] & departures["cylinder"][1]
    for band, low, high in (("crest", 0.0, 0.15), ("flanks", 0.3, 1.0)):
        bins = lit & (nx >= low) & (nx < high)
        assert bins.sum() >= 10, band
        means, errors = {}, {}
        for kind, (departure, _) in departures.items():
            means[kind] = float(departure[bins].mean())
            errors[kind] = float(departure[bins].std(ddof=1)) / math.sqrt(bins.sum())
        ratio = means["cylinder"] / means["sphere"]
        error = ratio * math.hypot(errors["cylinder"] / means["cylinder"], errors["sphere"] / means["sphere"])
        print(f"{band}: sph {means['sphere']:.1f} cyl {means['cylinder']:.1f}, {ratio:.2f} ± {error:.2f}")
        assert means["cylinder"] > LAB_JND + 4.0 * errors["cylinder"]
        if band == "crest":
            assert ratio > visibility(0.15) - 4.0 * error, (ratio, error, visibility(0.15))
        else:  # where the paper's reading fades the colour, it stays
            assert ratio > visibility(0.3) + 4.0 * error, (ratio, error, visibility(0.3))


@pytest.mark.slow
def test_cylinder_source_coherence_is_short_along_its_axis_only(tmp_path: Path) -> None:
    """Fig. 7: on the lit rim the tube (length L) gives ℓ₂ = r·√12/(k·L) (a uniform strip's VCZ,
    M = (k/r)²L²/12) and a strongly anisotropic coherence; the sphere of the same power a far rounder one.

    Tolerance: 3 % for the strip model (the tube's width, the rim's spread of view angles and of r),
    plus 3 standard errors of the median ℓ₂ over the rim's pixels (which pixels pass the brightness cut
    and their ℓ₂ vary with the samples at 16 spp: SE ≈ 1.2533·σ/√n, σ from the interquartile range)."""
    diagnostics = {}
    for kind in ("sphere", "cylinder"):
        name = f"fig7_thin_film_{kind}_light"
        image = render(name, tmp_path, 96, 16)
        values = coherence(tmp_path / name)
        pixels = brightest_material_pixels(image, values["albedo"], 0.05)
        assert pixels.sum() >= 20
        diagnostics[kind] = {
            key: float(np.median(values[key][pixels])) for key in ("l2_um", "r_m", "anisotropy")
        }
        quartiles = np.percentile(values["l2_um"][pixels], [25.0, 75.0])
        sigma = (quartiles[1] - quartiles[0]) / 1.349
        diagnostics[kind]["l2_median_se_um"] = 1.2533 * sigma / math.sqrt(pixels.sum())
    cylinder = diagnostics["cylinder"]
    (tube,) = example("fig7_thin_film_cylinder_light")["emitters"]
    length_m = float(np.linalg.norm(np.subtract(tube["p1_m"], tube["p0_m"])))
    expected_l2_um = cylinder["r_m"] * math.sqrt(12.0) / (K_550_PER_M * length_m) * 1e6
    tolerance_um = 0.03 * expected_l2_um + 3.0 * cylinder["l2_median_se_um"]
    assert cylinder["l2_um"] == pytest.approx(expected_l2_um, abs=tolerance_um)
    assert cylinder["anisotropy"] > 4.0
    assert diagnostics["sphere"]["anisotropy"] < 2.5


@pytest.mark.slow
def test_mirror_fed_flank_receives_the_more_coherent_light(tmp_path: Path) -> None:
    """Fig. 8: the mirror keeps Θ and adds path length, so the right flank (lit via the mirror) sees the
    source from the virtual image's distance r' and ℓ = 2r/(k·a) (a uniform disk of radius a, M = (k/r)²a²/4)
    grows with it: ℓ_right/ℓ_left = r'/r. The rim distances are checked against the scene's geometry."""
    name = "fig8_mirror_coherence"
    scene = example(name, width=96, height=96, spp=32)
    # The rough neighbour plays no part here; without it the coated shell's flanks are the only lit
    # surfaces with |n_x| > 0.3 in front of the mirror.
    scene["shapes"] = [shape for shape in scene["shapes"] if shape["material"] != "rough_copper"]
    image = render(name, tmp_path, 96, 32, scene)
    values = coherence(tmp_path / name)
    (light,) = scene["emitters"]
    mirror = next(shape for shape in scene["shapes"] if shape["material"] == "mirror")
    normal = np.asarray(mirror["normal"]) / np.linalg.norm(mirror["normal"])
    light_m = np.asarray(light["center_m"])
    virtual_m = light_m - 2.0 * np.dot(light_m - mirror["center_m"], normal) * normal
    shell = scene["shapes"][0]
    centre_m, size_m = np.asarray(shell["center_m"]), max(shell["semi_axes_m"])
    radius_m = light["radius_m"]
    in_front = image.depth_m < np.linalg.norm(np.asarray(scene["camera"]["origin_m"]) - centre_m) + size_m
    flanks = {}
    # Pixels where that side's source dominates the backdrop's diffuse light (whose short VCZ coherence
    # also enters the luminance-weighted M): the direct highlight is bright, the mirror's caustic is sparse.
    sides = (("direct", image.normal[..., 0] < -0.3, 0.1), ("mirror", image.normal[..., 0] > 0.3, 0.005))
    for side, mask, threshold in sides:
        candidates = in_front & mask
        selected = candidates & (image.luminance > threshold * np.percentile(image.luminance[candidates], 99))
        assert selected.sum() >= 10, side
        flanks[side] = {key: float(np.median(values[key][selected])) for key in ("l1_um", "l2_um", "r_m")}
    assert flanks["direct"]["r_m"] == pytest.approx(np.linalg.norm(light_m - centre_m), abs=size_m)
    assert flanks["mirror"]["r_m"] == pytest.approx(np.linalg.norm(virtual_m - centre_m), abs=size_m)
    for side, flank in flanks.items():
        expected_um = 2.0 * flank["r_m"] / (K_550_PER_M * radius_m) * 1e6
        assert flank["l2_um"] == pytest.approx(expected_um, rel=0.1), side
    assert flanks["mirror"]["l2_um"] / flanks["direct"]["l2_um"] == pytest.approx(
        flanks["mirror"]["r_m"] / flanks["direct"]["r_m"], rel=0.1
    )


def test_film_modes_reach_the_grating(tmp_path: Path) -> None:
    """The large-source DVD (a grating and a diffuse backdrop only, so only the grating reads the modes):
    with the same seed, 16 modes change the diffraction streak and nothing else — the pixels that change
    are the disc's (issue 26: the grating ignored ``film.modes``, the renders were bitwise equal)."""
    scene = example("fig1f_dvd_large_source", width=32, height=32, spp=8)
    one = render("one", tmp_path, 32, 8, {**scene, "film": {**scene["film"], "modes": 1}})
    sixteen = render("sixteen", tmp_path, 32, 8, {**scene, "film": {**scene["film"], "modes": 16}})
    changed = np.any(one.bands != sixteen.bands, axis=-1)
    assert changed.sum() >= 5
    disc = one.depth_m < 0.2  # the disc is ≈ 0.14 m from the camera; the backdrop ≥ 0.3 m
    assert np.all(disc[changed] | (sixteen.luminance[changed] < 1e-3 * one.luminance.max()))


# --- Fig. 9: 1 vs 16 modes -----------------------------------------------------------------------


@pytest.mark.slow
def test_sixteen_modes_differ_from_one_mode_only_slightly(tmp_path: Path) -> None:
    """Fig. 9: with the same seed (the same paths) the 1- and 16-mode renders differ by ΔE₀₀ well under the
    just-noticeable 1 over most of the image, and by something (the modes are used) where light met the
    disc's grating or the coated shell: were the modes unused, every pixel would be bitwise the same
    (ΔE₀₀ = 0). At 48² × 16 spp 3.1–3.6 % of the pixels differ over seeds 0–4; how much the most changed
    one differs depends on the paths a seed draws (max ΔE₀₀ 0.001–0.011), so the test counts pixels."""
    from hgcore.image_metrics import delta_e00_map

    one = render("fig9_modes_1", tmp_path, 48, 16)
    sixteen = render("fig9_modes_16", tmp_path, 48, 16)
    assert np.all(np.isfinite(sixteen.bands))
    exposure_ev = -math.log2(np.percentile(one.luminance, 99))
    delta_e = delta_e00_map(one.bands, sixteen.bands, one.wavelengths_nm, exposure_ev)
    assert np.median(delta_e) < 0.5
    assert np.percentile(delta_e, 90) < 1.0
    assert np.mean(delta_e > 0.0) > 0.01
