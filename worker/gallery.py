"""The gallery: the paper's figures as example scenes, rendered into ``gallery/`` and ``docs/gallery.md``.

``python -m worker.gallery [--size PX] [--spp N] [--only NAME ...] [--defaults]`` renders every scene of
:data:`GALLERY` (``schemas/examples/<name>.json``) with its film overridden to ``--size``² and ``--spp``
(publication quality by default: 512², :data:`PUBLICATION_SPP`), writes ``image.exr``, ``variance.exr``,
``preview.png`` and ``summary.json`` (with ``wall_s``) into ``gallery/<name>/``, copies the preview to
``docs/gallery/<name>.png`` and regenerates ``docs/gallery.md`` from this table and the summaries. With
``--defaults`` each scene renders at its own film settings instead (what ``hgrender render`` does; the
gallery promises those finish in ≤ 60 s on 2 cores).
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hgcore.files import atomic_write_bytes
from schemas import EXAMPLES_DIR

ROOT = Path(__file__).resolve().parents[1]
GALLERY_DIR = ROOT / "gallery"
DOCS_IMAGES_DIR = ROOT / "docs" / "gallery"
DOC_PATH = ROOT / "docs" / "gallery.md"
PUBLICATION_SIZE_PX = 512
PUBLICATION_SPP = 256


@dataclass(frozen=True)
class GalleryEntry:
    """One gallery scene: the example's file stem, the paper figure it reproduces and what to look for."""

    name: str
    figure: str
    paper_time: str
    look_for: str
    viewer_view: str  # the viewer's most telling view for this scene (web/js/examples.js mirrors it)


GALLERY: tuple[GalleryEntry, ...] = (
    GalleryEntry(
        "fig1f_dvd_small_source",
        "Fig. 1(f), right disc",
        "Fig. 1: 90 000 spp, ~3 days (whole figure)",
        "The first order's rainbow streak on the near half (red by the hole, violet at the rim) and a "
        "fainter second rainbow (the 3rd order; the 2nd is weak at duty 0.35) on the far half. The tracks "
        "are concentric (the optical disc's radial tangent), so each order is a radial streak.",
        "image",
    ),
    GalleryEntry(
        "fig1f_dvd_large_source",
        "Fig. 1(f), left disc",
        "Fig. 1: 90 000 spp, ~3 days (whole figure)",
        "The same disc under a 6× larger sphere of the same power: the streaks widen (each point of the "
        "source draws its own rainbow) and the higher orders on the far half are dimmer relative to the "
        "first: Eq. 20 attenuates order m by the incident coherence at the m-th lobe's offset, which a "
        "larger source (shorter coherence) shrinks more for larger m.",
        "image",
    ),
    GalleryEntry(
        "fig7_thin_film_sphere_light",
        "Fig. 7 (left)",
        "10 000 spp, ~4 hours",
        "A 14.6 cm ribbed silver shell with a 1.23 µm coating, back-lit at grazing incidence by a 0.6 cm "
        "F11 sphere 60 cm away: interference colours along the lit rim, changing with the angle.",
        "image",
    ),
    GalleryEntry(
        "fig7_thin_film_cylinder_light",
        "Fig. 7 (right)",
        "10 000 spp, ~4 hours",
        "The same shell under a 20 cm × 0.1 cm tube of the same spectrum and power: the tube's coherence is "
        "long along its axis and short across it, so the film's fringes survive only where the normal is "
        "perpendicular to the axis (the middle of the rim) and wash out towards the shell's ends. Open it "
        "in the viewer with ellipses on to see the anisotropy.",
        "ellipses",
    ),
    GalleryEntry(
        "fig8_mirror_coherence",
        "Fig. 8 (left)",
        "8192 spp",
        "A coated gold shell lit directly on its left flank and via a silver mirror on its right: the "
        "mirror keeps the coherence and adds path length, so the right flank's interference is more "
        "pronounced. The rough copper neighbour diffuses weakly coherent light.",
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
        "The same scene with 16 HG modes: compare with the 1-mode image (the viewer's ΔE₀₀ compare); the "
        "differences sit on the diffraction lobes and the surfaces they light.",
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


def gallery_scene(entry: GalleryEntry, size_px: int | None, spp: int | None) -> dict[str, Any]:
    """The example scene of ``entry`` with its film overridden (None keeps the example's own value)."""
    scene = json.loads((EXAMPLES_DIR / f"{entry.name}.json").read_text())
    if size_px is not None:
        scene["film"] = {**scene["film"], "width": size_px, "height": size_px}
    if spp is not None:
        scene["film"] = {**scene["film"], "spp": spp}
    return scene


def render_entry(entry: GalleryEntry, size_px: int | None, spp: int | None, out_dir: Path) -> dict[str, Any]:
    """Render one entry into ``out_dir``; its summary.json gains ``wall_s`` and ``gallery`` fields."""
    from worker.render.api import render_scene

    scene = gallery_scene(entry, size_px, spp)
    out_dir.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    summary = render_scene(scene, out_dir, spp=scene["film"]["spp"])
    wall_s = time.perf_counter() - start
    summary = {
        **summary,
        "wall_s": round(wall_s, 2),
        "gallery": {"figure": entry.figure, "width": scene["film"]["width"], "spp": scene["film"]["spp"]},
    }
    atomic_write_bytes(out_dir / "summary.json", json.dumps(summary, indent=2, sort_keys=True).encode())
    return summary


def write_doc(summaries: dict[str, dict[str, Any]]) -> None:
    """docs/gallery.md from :data:`GALLERY` and the summaries of the rendered entries."""
    lines = [
        "# Gallery",
        "",
        "The paper's phenomena as example scenes (`schemas/examples/<name>.json`). Regenerate with",
        "`make gallery` (`python -m worker.gallery`: renders every scene at 512² into `gallery/<name>/` and",
        "rewrites this page; `--size`/`--spp` override, `--defaults` renders at each example's own film,",
        "which `hgrender render` uses and which finishes in ≤ 60 s on 2 cores). Times below are wall-clock",
        "on the shared 2-core development machine, so they are upper bounds.",
        "",
        "Preview exposure (`hgcore.imaging.preview_exposure_ev`): the 99.8th percentile of each pixel's",
        "brightest channel max(R, G, B) maps to 1, so at most 0.2 % of the pixels (the emitter, glints) clip",
        "and no highlight loses its colour to white; the viewer opens at its own automatic exposure",
        "(luminance p99) and can be moved from there.",
        "",
    ]
    for entry in GALLERY:
        summary = summaries.get(entry.name)
        lines += [f"## {entry.figure}: `{entry.name}`", ""]
        if summary is not None:
            gallery = summary["gallery"]
            lines += [
                f"![{entry.name}](gallery/{entry.name}.png)",
                "",
                f"Rendered at {gallery['width']}² with {gallery['spp']} spp in {summary['wall_s']:.0f} s "
                f"(paper: {entry.paper_time}).",
                "",
            ]
        else:
            lines += [f"Not rendered yet (paper: {entry.paper_time}).", ""]
        lines += [f"What to look for: {entry.look_for}", ""]
    atomic_write_bytes(DOC_PATH, "\n".join(lines).encode())


def _existing_summaries() -> dict[str, dict[str, Any]]:
    summaries = {}
    for entry in GALLERY:
        path = GALLERY_DIR / entry.name / "summary.json"
        if path.is_file() and (DOCS_IMAGES_DIR / f"{entry.name}.png").is_file():
            summaries[entry.name] = json.loads(path.read_text())
    return summaries


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m worker.gallery", description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=PUBLICATION_SIZE_PX, help="film width = height, px")
    parser.add_argument("--spp", type=int, default=PUBLICATION_SPP, help="samples per pixel")
    parser.add_argument("--only", nargs="*", default=None, help="gallery names to render (default: all)")
    parser.add_argument("--defaults", action="store_true", help="render at each example's own film")
    args = parser.parse_args(argv)
    names = {entry.name for entry in GALLERY}
    unknown = set(args.only or ()) - names
    if unknown:
        parser.error(f"--only: unknown gallery scene(s) {', '.join(sorted(unknown))}")
    for entry in GALLERY:
        if args.only and entry.name not in args.only:
            continue
        out_dir = GALLERY_DIR / entry.name
        size, spp = (None, None) if args.defaults else (args.size, args.spp)
        summary = render_entry(entry, size, spp, out_dir)
        gallery = summary["gallery"]
        print(f"{entry.name}: {gallery['width']}² {gallery['spp']} spp {summary['wall_s']} s")
        if not args.defaults:
            DOCS_IMAGES_DIR.mkdir(parents=True, exist_ok=True)
            atomic_write_bytes(DOCS_IMAGES_DIR / f"{entry.name}.png", (out_dir / "preview.png").read_bytes())
    if not args.defaults:
        write_doc(_existing_summaries())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
