"""``hgrender render SCENE -o OUTDIR``: a local render without the service (progress bar on stderr)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hgrender.cli import CliError, positive_int, read_json_file
from hgrender.cli.progress import ProgressDisplay
from hgrender.cli.tev import TevImage, add_tev_option

if TYPE_CHECKING:
    from hgcore.settings import SceneLimits
    from schemas.scene import Scene

# With --tev and no --chunks, the render is split into this many chunks (at most spp) so that tev shows
# the image refine as each chunk is added.
TEV_DEFAULT_CHUNKS = 8


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("render", help="render a scene locally (no service)")
    parser.add_argument(
        "scene", type=Path, help="scene file: JSON (hgrender/scene/v1) or USD (.usda/.usdc/.usdz)"
    )
    parser.add_argument("-o", "--output", type=Path, required=True, help="output directory")
    parser.add_argument("--spp", type=int, help="samples per pixel (overrides the scene's film.spp)")
    parser.add_argument("--seed", type=int, help="random seed (overrides film.seed)")
    parser.add_argument("--modes", type=int, help="HG transverse modes 1..16 (overrides film.modes)")
    parser.add_argument(
        "--chunks",
        type=positive_int,
        default=None,
        help=f"render in K chunks and merge (default 1; with --tev {TEV_DEFAULT_CHUNKS})",
    )
    add_quality_options(parser)
    parser.add_argument(
        "--variant",
        choices=("auto", "llvm_ad_spectral", "cuda_ad_spectral"),
        help="Mitsuba variant (default: HGRENDER_VARIANT or auto)",
    )
    add_tev_option(parser, "after every chunk")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(handler=run)


def add_quality_options(parser: argparse.ArgumentParser) -> None:
    """The integrator and noise-target options, shared by ``render`` and ``submit`` (job options)."""
    parser.add_argument(
        "--integrator",
        choices=("hg_path", "rlt"),
        help="hg_path: partially coherent transport (PLT); rlt: the radiometric baseline, a coherent "
        "plane wave per sample (overrides film.integrator)",
    )
    parser.add_argument(
        "--target-rel-error",
        type=float,
        metavar="E",
        help="noise target: add passes until the relative standard error of every band's image mean "
        "(or, with --target-quantile, of the pixel luminance at that quantile) is at most E; --spp is "
        "then the first pass's spp",
    )
    parser.add_argument(
        "--time-budget-s",
        type=float,
        metavar="T",
        help="noise target: add passes while the render time stays within T seconds",
    )
    parser.add_argument(
        "--target-quantile",
        type=float,
        metavar="Q",
        help="measure --target-rel-error per pixel (luminance) at this quantile of the pixels, in (0, 1]",
    )


def load_scene_file(path: Path, limits: SceneLimits) -> tuple[Scene, Path | None]:
    """The scene, validated against ``limits`` (this process's settings), plus the bundle directory that
    relative asset paths resolve in."""
    if not path.is_file():
        raise CliError(f"scene: no such file {str(path)!r}")
    suffix = path.suffix.lower()
    if suffix == ".json":
        from schemas.validation import validate_scene

        return validate_scene(read_json_file(path, "scene"), limits), path.parent
    if suffix in (".usda", ".usdc", ".usdz", ".usd", ".zip"):
        from schemas.usd_import import import_usd_isolated

        return import_usd_isolated(path, path.parent, limits), path.parent
    raise CliError(f"scene: unsupported file type {suffix!r} (use .json, .usda, .usdc, .usdz or .zip)")


def run(args: argparse.Namespace) -> int:
    import contextlib

    from hgcore.settings import Settings
    from worker.mitsuba_setup import configure_mitsuba

    settings = Settings()  # this process's one: scene limits, Mitsuba variant and thread count
    parsed, bundle_dir = load_scene_file(args.scene, settings)
    configure_mitsuba(args.variant or settings.variant, settings.render_threads)
    from hgcore.noise_target import NoiseTarget
    from worker.render.chunks import render_scene

    target = NoiseTarget.from_options(args.target_rel_error, args.time_budget_s, args.target_quantile)
    chunks = args.chunks if args.chunks is not None else (TEV_DEFAULT_CHUNKS if args.tev else 1)
    with contextlib.ExitStack() as stack:
        # tev first: a tev that is not running is reported before any rendering starts.
        tev = stack.enter_context(TevImage(args.tev, f"hgrender {args.scene.stem}")) if args.tev else None
        display = stack.enter_context(ProgressDisplay("render", enabled=not args.quiet))
        summary = render_scene(
            parsed,
            args.output,
            spp=args.spp,
            seed=args.seed,
            modes=args.modes,
            integrator=args.integrator,
            chunks=chunks,
            progress=display.update,
            bundle_dir=bundle_dir,
            limits=settings,
            on_chunk=None if tev is None else lambda sums: tev.show(channels_of_sums(sums, parsed.film)),
            target=target,
        )
    print(
        json.dumps(
            {
                "output": str(args.output),
                "spp": summary["spp"],
                "samples_per_second": summary["samples_per_second"],
                "files": summary["files"],
                **({"noise_target": summary["noise_target"]} if "noise_target" in summary else {}),
            }
        )
    )
    return 0


def channels_of_sums(sums: Any, film: Any) -> dict[str, Any]:
    """``image.exr``'s channels (name → (H, W) array) of the chunks' running sum, without writing it."""
    from hgcore.artifacts.images import channels_from_sums
    from hgcore.artifacts.layout import BandLayout

    return channels_from_sums(sums, BandLayout(film.wavelength_min_nm, film.wavelength_max_nm, film.bands))
