"""The gallery: the paper's figures as example scenes, rendered into ``gallery/`` and ``docs/gallery.md``.

``python -m worker.gallery [--size PX] [--spp N] [--only NAME ...] [--defaults]`` renders every scene of
:data:`GALLERY` (``schemas/examples/<name>.json``) with its film overridden to ``--size``² and ``--spp``
(publication quality by default: 512², :data:`PUBLICATION_SPP`), writes ``image.exr``, ``variance.exr``,
``preview.png`` and ``summary.json`` (with ``wall_s``) into ``gallery/<name>/``, copies the preview to
``docs/gallery/<name>.png`` (and a thumbnail to ``schemas/examples/thumbnails/``, the viewer's one-click
examples), and regenerates ``docs/gallery.md`` from this table and the summaries. With
``--defaults`` each scene renders at its own film settings instead (what ``hgrender render`` does; the
gallery promises those finish in ≤ 60 s on 2 cores).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

from hgcore.files import atomic_write_bytes
from hgcore.settings import Settings
from schemas import EXAMPLES_DIR, validate_scene
from schemas.gallery import GALLERY, THUMBNAIL_SIZE_PX, THUMBNAILS_DIR, GalleryEntry
from worker.mitsuba_setup import configure_mitsuba

ROOT = Path(__file__).resolve().parents[1]
GALLERY_DIR = ROOT / "gallery"
DOCS_IMAGES_DIR = ROOT / "docs" / "gallery"
DOC_PATH = ROOT / "docs" / "gallery.md"
#: ``bench/bench_convergence.py``'s results, summarised in the doc's last section when present.
CONVERGENCE_JSON = ROOT / "bench" / "results" / "convergence.json"
PUBLICATION_SIZE_PX = 512
PUBLICATION_SPP = 256
#: Chunks a gallery render is split into: progress is reported after each.
PROGRESS_CHUNKS = 8


def gallery_scene(entry: GalleryEntry, size_px: int | None, spp: int | None) -> dict[str, Any]:
    """The example scene of ``entry`` with its film overridden (None keeps the example's own value)."""
    scene = json.loads((EXAMPLES_DIR / f"{entry.name}.json").read_text())
    if size_px is not None:
        scene["film"] = {**scene["film"], "width": size_px, "height": size_px}
    if spp is not None:
        scene["film"] = {**scene["film"], "spp": spp}
    return scene


def camera_description(entry: GalleryEntry) -> str:
    """The example's camera in words: its aperture sets how much of a source a smooth film shows a pixel
    (docs/physics_interactions.md §3, "What a pixel sees")."""
    camera = gallery_scene(entry, None, None)["camera"]
    radius_m = float(camera.get("aperture_radius_m", 0.0))
    if radius_m <= 0.0:
        return "a pinhole (each ray of a pixel sees one direction of a source in a mirror-like film)"
    focus = camera.get("focus_distance_m")
    focus_text = f"{focus} m" if focus is not None else "its target"
    return f"a thin lens of radius {radius_m * 1e3:g} mm focused at {focus_text}"


def render_entry(
    entry: GalleryEntry, size_px: int | None, spp: int | None, out_dir: Path, settings: Settings
) -> dict[str, Any]:
    """Render one entry into ``out_dir`` under this process's ``settings`` (its scene limits); its
    summary.json gains ``wall_s`` and ``gallery`` fields."""
    from worker.render.chunks import render_scene

    scene = gallery_scene(entry, size_px, spp)
    out_dir.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()

    def progress(fraction: float) -> None:  # long renders show progress (one stderr line, redrawn)
        print(f"\r{entry.name}: {fraction:6.1%}", end="", file=sys.stderr, flush=True)

    summary = render_scene(
        validate_scene(scene, settings),
        out_dir,
        chunks=PROGRESS_CHUNKS,
        progress=progress,
        limits=settings,
    )
    print(file=sys.stderr)
    wall_s = time.perf_counter() - start
    summary = {
        **summary,
        "wall_s": round(wall_s, 2),
        "gallery": {"figure": entry.figure, "width": scene["film"]["width"], "spp": scene["film"]["spp"]},
    }
    atomic_write_bytes(out_dir / "summary.json", json.dumps(summary, indent=2, sort_keys=True).encode())
    return summary


def write_thumbnail(preview: Path, thumbnail: Path) -> None:
    """The viewer's one-click example thumbnail: the preview downscaled (Lanczos) to THUMBNAIL_SIZE_PX."""
    import io

    from PIL import Image

    image = Image.open(preview).convert("RGB")
    image.thumbnail((THUMBNAIL_SIZE_PX, THUMBNAIL_SIZE_PX), Image.Resampling.LANCZOS)
    buffer = io.BytesIO()
    image.save(buffer, format="PNG", optimize=True)
    thumbnail.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(thumbnail, buffer.getvalue())


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
    if summaries:
        total_s = sum(summary["wall_s"] for summary in summaries.values())
        lines += [f"Total render time of the {len(summaries)} scenes below: {total_s / 60:.1f} min.", ""]
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
        lines += [f"Camera: {camera_description(entry)}.", ""]
        lines += [f"What to look for: {entry.look_for}", ""]
    lines += convergence_section()
    atomic_write_bytes(DOC_PATH, "\n".join(lines).encode())


def convergence_section(path: Path = CONVERGENCE_JSON) -> list[str]:
    """The doc's "PLT vs RLT" section from ``bench/bench_convergence.py``'s results (none without them):
    the plot and, per scene and integrator, where ΔE₀₀ p95 first falls below 1."""
    if not path.is_file():
        return []
    results = json.loads(path.read_text())
    lines = [
        "## PLT (`hg_path`) vs RLT (`rlt`): error vs spp and time",
        "",
        "`python -m bench.bench_convergence` (results: `bench/results/convergence.json`): each scene at "
        f"{results['resolution_px']}² rendered with both integrators at {results['levels_spp'][0]}…"
        f"{results['levels_spp'][-1]} spp (prefixes of one run) against an `hg_path` reference; ΔE₀₀ at the "
        "exposure mapping the reference's luminance p99 to white. Solid: Fig. 7 (sphere source); dashed: "
        "Fig. 8; dotted grey: each reference's own p95 (half that of its two halves' difference); "
        f"black dashes: p95 = {results['threshold_delta_e00_p95']:g}. Bench wall time "
        f"{results['wall_s'] / 60:.1f} min. Times are the levels' render time on the shared 2-core machine "
        "(warm kernels); the extrapolated times use the median time per spp. The extrapolation takes the "
        "reference's own p95 out in quadrature. A ratio of the last two levels' p95 near 1/√2 says the "
        "error is still Monte Carlo noise; a bias (RLT's mean where it disagrees with PLT) would show as a "
        "ratio towards 1.",
        "",
        "![ΔE₀₀ p95 vs spp and vs render time](gallery/convergence.svg)",
        "",
        "| scene | integrator | ΔE₀₀ p95 < 1 at | p95 at the last level | mean ΔE₀₀ there | p95 ratio of the "
        "last two levels (1/√2 = 0.71 for pure noise) | reference: spp, own p95 |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, scene in results["scenes"].items():
        reference = scene["reference"]
        for integrator in ("hg_path", "rlt"):
            run = scene[integrator]
            reached, last = run["reaches_p95_below_1"], run["levels"][-1]
            if reached["spp"] is not None:
                at = f"{reached['spp']} spp, {reached['seconds']:.1f} s"
            else:
                at = (
                    f"not by {last['spp']} spp; N^−½ extrapolation: {reached['extrapolated_spp']} spp, "
                    f"{reached['extrapolated_seconds']:.0f} s"
                )
            ratio = run["p95_ratio_last_two"]
            lines.append(
                f"| `{name}` | `{integrator}` | {at} | {last['delta_e00_p95']:.2f} | "
                f"{last['delta_e00_mean']:.2f} | {ratio:.2f} | {reference['spp']}, "
                f"{reference['delta_e00_p95']:.2f} |"
            )
    return [*lines, ""]


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
    settings = Settings()
    configure_mitsuba(settings.variant, settings.render_threads)
    names = {entry.name for entry in GALLERY}
    unknown = set(args.only or ()) - names
    if unknown:
        parser.error(f"--only: unknown gallery scene(s) {', '.join(sorted(unknown))}")
    for entry in GALLERY:
        if args.only and entry.name not in args.only:
            continue
        out_dir = GALLERY_DIR / entry.name
        size, spp = (None, None) if args.defaults else (args.size, args.spp)
        summary = render_entry(entry, size, spp, out_dir, settings)
        gallery = summary["gallery"]
        print(f"{entry.name}: {gallery['width']}² {gallery['spp']} spp {summary['wall_s']} s")
        if not args.defaults:
            DOCS_IMAGES_DIR.mkdir(parents=True, exist_ok=True)
            atomic_write_bytes(DOCS_IMAGES_DIR / f"{entry.name}.png", (out_dir / "preview.png").read_bytes())
            write_thumbnail(out_dir / "preview.png", THUMBNAILS_DIR / f"{entry.name}.png")
    if not args.defaults:
        write_doc(_existing_summaries())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
