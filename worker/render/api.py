"""The renderer's public interface: plan chunks, render a chunk, merge chunks, render a whole scene.

A render of S samples per pixel with seed s splits into K chunks of ⌈S/K⌉ or ⌊S/K⌋ spp with distinct
derived seeds; each chunk writes its per-pixel sums to a ``.npz`` partial, and the merge adds them. The
merged image therefore has exactly S samples per pixel and the same expectation as an unsplit render
(the unsplit render is the K = 1 plan, so it is bitwise reproducible given S and s).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hgcore.artifacts.images import (
    coherence_statistics,
    images_from_sums,
    write_images,
    write_summary,
)
from hgcore.artifacts.layout import SUMMARY_JSON, BandLayout
from hgcore.artifacts.pixel_sums import PixelSums, read_partial, write_partial
from hgcore.errors import InputError
from schemas.scene import Scene
from schemas.validation import validate_scene
from worker.render.renderer import Renderer
from worker.render.scene_compiler import SceneCompiler

ProgressCallback = Callable[[float], None]


@dataclass(frozen=True)
class ChunkSpec:
    index: int
    spp: int
    seed: int


def plan_chunks(total_spp: int, chunk_count: int, base_seed: int) -> list[ChunkSpec]:
    """Split ``total_spp`` into ``chunk_count`` chunks (≥ 1 spp each) with distinct seeds."""
    if total_spp < 1:
        raise InputError(f"spp: must be at least 1, got {total_spp}")
    if chunk_count < 1:
        raise InputError(f"chunks: must be at least 1, got {chunk_count}")
    chunk_count = min(chunk_count, total_spp)
    base, extra = divmod(total_spp, chunk_count)
    return [
        ChunkSpec(index, base + (1 if index < extra else 0), (base_seed + 0x632BE5AB * index) & 0xFFFFFFFF)
        for index in range(chunk_count)
    ]


def as_scene(scene: Scene | dict[str, Any]) -> Scene:
    return scene if isinstance(scene, Scene) else validate_scene(scene)


_renderers: dict[str, Renderer] = {}


def renderer_for(scene: Scene, bundle_dir: Path | None = None) -> Renderer:
    """A Renderer for ``scene``, reused within a process for identical scenes (load once, kernels cached)."""
    from worker.mitsuba_setup import load_mitsuba

    key = scene.model_dump_json(by_alias=True) + str(bundle_dir)
    if key not in _renderers:
        compiled = SceneCompiler(load_mitsuba(), bundle_dir).compile(scene)
        _renderers.clear()  # one scene at a time keeps worker memory bounded
        _renderers[key] = Renderer(compiled)
    return _renderers[key]


@dataclass(frozen=True)
class RenderedChunk:
    """One chunk's per-pixel sums and how long its render took (seconds, wall clock)."""

    chunk: ChunkSpec
    sums: PixelSums
    seconds: float
    pixels: int

    @property
    def samples(self) -> int:
        return self.chunk.spp * self.pixels

    def result(self) -> dict[str, Any]:
        return {
            "index": self.chunk.index,
            "spp": self.chunk.spp,
            "samples": self.samples,
            "seconds": self.seconds,
            "samples_per_second": self.samples / self.seconds if self.seconds > 0 else None,
        }


def render_chunk_sums(
    scene: Scene | dict[str, Any],
    chunk: ChunkSpec,
    *,
    progress: ProgressCallback | None = None,
    should_stop: Callable[[], bool] | None = None,
    bundle_dir: Path | None = None,
) -> RenderedChunk:
    """Render one chunk and keep its per-pixel sums in memory."""
    parsed = as_scene(scene)
    start = time.perf_counter()
    renderer = renderer_for(parsed, bundle_dir)
    sums = renderer.render_sums(chunk.spp, chunk.seed, progress=progress, should_stop=should_stop)
    return RenderedChunk(chunk, sums, time.perf_counter() - start, renderer.width * renderer.height)


def save_chunk(rendered: RenderedChunk, out_path: Path) -> None:
    """Write a chunk's sums to ``out_path`` (.npz, atomic), the partial that ``merge_chunks`` adds up."""
    write_partial(out_path, rendered.sums, rendered.seconds, rendered.chunk.index, rendered.chunk.seed)


def render_chunk(
    scene: Scene | dict[str, Any],
    chunk: ChunkSpec,
    out_path: Path,
    *,
    progress: ProgressCallback | None = None,
    should_stop: Callable[[], bool] | None = None,
    bundle_dir: Path | None = None,
) -> dict[str, Any]:
    """Render one chunk and write its per-pixel sums to ``out_path`` (.npz, atomic)."""
    rendered = render_chunk_sums(
        scene, chunk, progress=progress, should_stop=should_stop, bundle_dir=bundle_dir
    )
    save_chunk(rendered, out_path)
    return rendered.result()


def load_chunks(paths: Sequence[Path]) -> tuple[list[PixelSums], float]:
    """The chunks' sums, in the order given, and their render time summed (seconds)."""
    loaded = [read_partial(Path(path)) for path in paths]
    return [sums for sums, _ in loaded], sum(seconds for _, seconds in loaded)


def merge_chunks(
    scene: Scene | dict[str, Any],
    chunk_paths: Sequence[Path],
    out_dir: Path,
    *,
    extra_summary: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Add the chunks' sums and write image.exr, variance.exr, preview.png and summary.json."""
    if not chunk_paths:
        raise InputError("chunk_paths: at least one chunk is needed")
    chunk_sums, render_seconds = load_chunks(sorted(chunk_paths, key=lambda p: str(p)))
    return write_merged(scene, chunk_sums, render_seconds, out_dir, extra_summary=extra_summary)


def write_merged(
    scene: Scene | dict[str, Any],
    chunk_sums: Sequence[PixelSums],
    render_seconds: float,
    out_dir: Path,
    *,
    extra_summary: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Add chunks' sums (in memory) and write image.exr, variance.exr, preview.png and summary.json.
    ``render_seconds``: the chunks' render time, summed."""
    parsed = as_scene(scene)
    if not chunk_sums:
        raise InputError("chunk_sums: at least one chunk is needed")
    total = chunk_sums[0]
    for sums in chunk_sums[1:]:
        total = total.add(sums)
    film = parsed.film
    bands = BandLayout(film.wavelength_min_nm, film.wavelength_max_nm, film.bands)
    images = images_from_sums(total, bands)
    out_dir = Path(out_dir)
    files = write_images(images, bands, out_dir)
    samples = total.sample_count * film.width * film.height
    from worker.mitsuba_setup import load_mitsuba

    summary = {
        "scene": parsed.name,
        "width": film.width,
        "height": film.height,
        "spp": total.sample_count,
        "bands": film.bands,
        "band_centers_nm": bands.centers_nm.tolist(),
        "modes": film.modes,
        "max_depth": film.max_depth,
        "chunks": len(chunk_sums),
        "variant": load_mitsuba().variant(),
        "render_seconds": render_seconds,
        "samples": samples,
        "samples_per_second": samples / render_seconds if render_seconds > 0 else None,
        "coherence": coherence_statistics(images),
        "files": [*files, SUMMARY_JSON],
        **(extra_summary or {}),
    }
    write_summary(out_dir, summary)
    return summary


def render_scene(
    scene: Scene | dict[str, Any],
    out_dir: Path,
    *,
    spp: int | None = None,
    seed: int | None = None,
    modes: int | None = None,
    integrator: str | None = None,
    chunks: int = 1,
    progress: ProgressCallback | None = None,
    bundle_dir: Path | None = None,
    on_chunk: Callable[[PixelSums], None] | None = None,
) -> dict[str, Any]:
    """Render locally (chunks run one after another) and write the final artifacts to ``out_dir``.
    ``on_chunk(sums)`` gets the running sum of the chunks finished so far after each one (previews)."""
    parsed = as_scene(scene)
    overrides = {
        key: value
        for key, value in (("spp", spp), ("seed", seed), ("modes", modes), ("integrator", integrator))
        if value is not None
    }
    if overrides:
        parsed = validate_scene({**parsed.to_json_dict(), "film": {**parsed.film.model_dump(), **overrides}})
    out_dir = Path(out_dir)
    plan = plan_chunks(parsed.film.spp, chunks, parsed.film.seed)
    partial_dir = out_dir / ".chunks"
    paths = []
    done_spp = 0
    running: PixelSums | None = None
    for chunk in plan:

        def chunk_progress(fraction: float, chunk: ChunkSpec = chunk, done: int = done_spp) -> None:
            if progress is not None:
                progress((done + fraction * chunk.spp) / parsed.film.spp)

        path = partial_dir / f"{chunk.index:04d}.npz"
        rendered = render_chunk_sums(parsed, chunk, progress=chunk_progress, bundle_dir=bundle_dir)
        save_chunk(rendered, path)
        paths.append(path)
        done_spp += chunk.spp
        if on_chunk is not None:
            running = rendered.sums if running is None else running.add(rendered.sums)
            on_chunk(running)
    summary = merge_chunks(parsed, paths, out_dir)
    for path in paths:
        path.unlink(missing_ok=True)
    partial_dir.rmdir()
    return summary
