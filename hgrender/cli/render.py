"""``hgrender render SCENE -o OUTDIR``: a local render without the service (progress bar on stderr)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from hgrender.cli import CliError


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("render", help="render a scene locally (no service)")
    parser.add_argument(
        "scene", type=Path, help="scene file: JSON (hgrender/scene/v1) or USD (.usda/.usdc/.usdz)"
    )
    parser.add_argument("-o", "--output", type=Path, required=True, help="output directory")
    parser.add_argument("--spp", type=int, help="samples per pixel (overrides the scene's film.spp)")
    parser.add_argument("--seed", type=int, help="random seed (overrides film.seed)")
    parser.add_argument("--modes", type=int, help="HG transverse modes 1..16 (overrides film.modes)")
    parser.add_argument("--chunks", type=int, default=1, help="render in K chunks and merge (default 1)")
    parser.add_argument(
        "--variant",
        choices=("auto", "llvm_ad_spectral", "cuda_ad_spectral"),
        help="Mitsuba variant (default: HGRENDER_VARIANT or auto)",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(handler=run)


def load_scene_file(path: Path) -> tuple[dict, Path | None]:
    """The scene as a JSON dict plus the bundle directory that relative asset paths resolve in."""
    if not path.is_file():
        raise CliError(f"scene: no such file {str(path)!r}")
    suffix = path.suffix.lower()
    if suffix == ".json":
        try:
            return json.loads(path.read_text()), path.parent
        except json.JSONDecodeError as error:
            raise CliError(f"scene: {path} is not valid JSON: {error}") from None
    if suffix in (".usda", ".usdc", ".usdz", ".usd", ".zip"):
        from schemas.usd_import import import_usd_isolated

        scene = import_usd_isolated(path, path.parent)
        return scene.to_json_dict(), path.parent
    raise CliError(f"scene: unsupported file type {suffix!r} (use .json, .usda, .usdc, .usdz or .zip)")


def run(args: argparse.Namespace) -> int:
    import os

    if args.variant:
        os.environ["HGRENDER_VARIANT"] = args.variant
    scene, bundle_dir = load_scene_file(args.scene)
    from tqdm import tqdm

    from schemas.validation import validate_scene
    from worker.render.api import render_scene

    parsed = validate_scene(scene)
    with tqdm(
        total=100,
        unit="%",
        disable=args.quiet,
        file=sys.stderr,
        desc="render",
        bar_format="{l_bar}{bar}| {n:.0f}/{total:.0f}% [{elapsed}<{remaining}]",
    ) as bar:

        def progress(fraction: float) -> None:
            bar.update(100 * fraction - bar.n)

        summary = render_scene(
            parsed,
            args.output,
            spp=args.spp,
            seed=args.seed,
            modes=args.modes,
            chunks=args.chunks,
            progress=progress,
            bundle_dir=bundle_dir,
        )
    print(
        json.dumps(
            {
                "output": str(args.output),
                "spp": summary["spp"],
                "samples_per_second": summary["samples_per_second"],
                "files": summary["files"],
            }
        )
    )
    return 0
