"""The gallery table: which example scenes reproduce which of the paper's figures, and how to look at them.

Data only (no rendering): ``worker.gallery`` renders these scenes into ``gallery/`` and ``docs/gallery.md``;
the service lists them as the viewer's one-click examples (``GET /v1/examples``: figure, view, thumbnail).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from schemas import EXAMPLES_DIR

#: Thumbnails of the gallery scenes (``make gallery`` writes them; the service serves them).
THUMBNAILS_DIR = EXAMPLES_DIR / "thumbnails"
THUMBNAIL_SIZE_PX = 128
#: ``image``: the spectral image; ``ellipses``: the image with the coherence ellipses drawn over it.
GalleryView = Literal["image", "ellipses"]


@dataclass(frozen=True)
class GalleryEntry:
    """One gallery scene: the example's file stem, the paper figure it reproduces and what to look for."""

    name: str
    figure: str
    paper_time: str
    look_for: str
    viewer_view: GalleryView  # the viewer's most telling view of a finished render


GALLERY: tuple[GalleryEntry, ...] = (
    GalleryEntry(
        "fig1f_dvd_small_source",
        "Fig. 1(f), right disc",
        "Fig. 1: 90 000 spp, ~3 days (whole figure)",
        "The first order's rainbow streak on the near half (red by the hole, violet at the rim) and a "
        "fainter second-order rainbow (violet to green, the grating equation at 2λ/d) on the far half. "
        "The tracks are concentric (the optical disc's radial tangent), so each order is a radial streak.",
        "image",
    ),
    GalleryEntry(
        "fig1f_dvd_large_source",
        "Fig. 1(f), left disc",
        "Fig. 1: 90 000 spp, ~3 days (whole figure)",
        "The same disc under a 6× larger sphere of the same power: the streaks widen (each point of the "
        "source draws its own rainbow). The higher orders keep their share (far/near half 0.048 vs 0.046 "
        "under the small source at 512², 256 spp): Eq. 20 attenuates order m through the incident "
        "coherence over the m-th lobe's offset, and ℓ = 2r/(ka) ≈ 2 µm here is still about three track "
        "pitches, so the attenuation is small; the paper's Fig. 1(f) shows it under less coherent light.",
        "image",
    ),
    GalleryEntry(
        "fig7_thin_film_sphere_light",
        "Fig. 7 (left)",
        "10 000 spp, ~4 hours",
        "A 14.6 cm ribbed silver shell (ribs 5 % deep) with a 0.30 µm weakly absorbing coating of index "
        "2.4 + 0.12i (`film_extinction` 0.12; optical path 2n_fτcos θ_t = 1.44 µm at normal incidence, the "
        "second order), lit from behind and above by a 0.6 cm F7 (daylight fluorescent) sphere 18 cm away. "
        "The coating is rough with a K-correlation spectrum (exponent 1.2, ℓc 0.5 µm), whose long tails "
        "light the whole back of the shell at incidence angles from near-normal to grazing, so the film's "
        "phase sweeps across what is lit: a cyan glint in an emerald-green band over the upper back, "
        "rose-mauve and brownish-violet bands below it and a lavender-grey front flank. Those are the "
        "film's interference colours (bare rough silver under the same light is a warm grey throughout: "
        "chromaticity spread 33 ± 1 vs 2.3 ± 0.2 CIELAB units, the former clear film's 3.9 ± 0.1; "
        "tests/integrator/test_gallery_phenomena.py). The absorption is what makes "
        "them vivid: a clear film on near-perfectly reflecting silver is Gires–Tournois-limited (R 0.73–0.97"
        " over 400–700 nm, pastel bands), while κ 0.12 attenuates the back-reflected beams (round trip "
        "e^{−4πκτ/λ} ≈ 0.44) until they match the top reflection |r₀₁| = 0.41 and the minima go deep (R "
        "0.003–0.47 at normal incidence; docs/physics_interactions.md §3). Bulk silver-sulfide tarnish "
        "(κ 0.3–1) would extinguish a 0.3 µm film's back-reflection; a thinner one would shear too little "
        "for the tube's contrast (right). The sphere's coherence (ℓ ≈ 3.5 µm, as measured) dwarfs the "
        "film's ~0.1 µm shear, so the fringes are fully visible.",
        "image",
    ),
    GalleryEntry(
        "fig7_thin_film_cylinder_light",
        "Fig. 7 (right)",
        "10 000 spp, ~4 hours",
        "The same shell under a 60 cm × 0.1 cm F7 tube (same spectrum and power) along x at the same "
        "place: its coherence is long across its axis (ℓ₁ ≈ 24 µm) and short along it (ℓ₂ = 0.087 µm = "
        "r√12/(kL), Eq. 14, as measured), below the film's shear (0.13 µm transverse at 45°). The paper's "
        "Eq. 18 (the whole tube's Σ⊥) would keep the fringes only where the normal is perpendicular to "
        "the axis. At this pinhole camera a pixel receives only the tube directions the coating's lobe "
        "passes (±0.34 rad of the ±1.2 rad tube, docs/physics_interactions.md §3), over which the light "
        "is coherent far beyond the shear: the emerald-green band runs along the whole crest, end to end, "
        "and the flanks keep their colours too. Measured against bare silver rendered with the same paths "
        "(96², 64 spp), the film's colour under the tube is 1.06 ± 0.08 of the sphere's on the crest "
        "(|n_x| < 0.15) and 1.75 ± 0.14 on the flanks (|n_x| ≥ 0.3), where the paper's reading fades it "
        "below 0.58. The fine coloured speckle is Monte Carlo noise of the tube's sampling (each sample "
        "carries 4 wavelengths). Open it in the viewer: the ellipses show the anisotropy (ℓ₁/ℓ₂ ≈ 290).",
        "ellipses",
    ),
    GalleryEntry(
        "fig8_mirror_coherence",
        "Fig. 8 (left)",
        "8192 spp",
        "A coated gold shell (2 µm film) lit directly on its left flank and via a silver mirror (top "
        "right) on its right by a 9 cm sphere: the mirror keeps the coherence and adds path length "
        "(r = 0.81 m instead of 0.54 m), so the right flank receives 1.5× longer coherence (ℓ = 2r/(ka): "
        "1.6 vs 1.05 µm, against a film shear of 1–1.5 µm), so Eq. 18 gives it the more pronounced "
        "interference. The larger source (9 cm, was 3 cm) is what lets the path tracer find the mirror "
        "path: the mirror-fed flank is now a filled yellow-green highlight (grainy at its rim), not a "
        "sparse caustic. The rough copper neighbour (lower left) diffuses weakly coherent light.",
        "ellipses",
    ),
    GalleryEntry(
        "fig9_modes_1",
        "Fig. 9 (left)",
        "16 384 spp, ~3.5 hours (half of the 16-mode time)",
        "A DVD and a coated shell in a white cyclorama: direct light and the disc's diffraction orders "
        "thrown onto the walls (indirect), with the 0th HG mode only.",
        "image",
    ),
    GalleryEntry(
        "fig9_modes_16",
        "Fig. 9 (middle)",
        "16 384 spp, ~7 hours",
        "The same scene with 16 HG modes: compare with the 1-mode image (the viewer's ΔE₀₀ compare). Since "
        "issue 26 the disc's lobes use the modes: each is the sphere's disk image blurred by the grating's "
        "own lobe (flatter-topped, its peak 0.6× the Gaussian's), so the differences sit on the diffraction "
        "streaks and are small in colour: the 4 mm sphere's image is about twice the DVD's intrinsic lobe.",
        "image",
    ),
    GalleryEntry(
        "fig1de_rough_metals",
        "Fig. 1(d, e)",
        "Fig. 1: 90 000 spp, ~3 days (whole figure)",
        "Rough gold (Gaussian PSD) and copper (ABC PSD) shells and a rippled rough silver sheet under a tube "
        "light: the scattered light's coherence is set by the surface statistics (coherence.* channels; "
        "the viewer's ellipses show its size and anisotropy).",
        "ellipses",
    ),
)

GALLERY_BY_NAME = {entry.name: entry for entry in GALLERY}
