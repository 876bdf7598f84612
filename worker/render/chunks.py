"""Chunked rendering, the renderer's public interface: plan chunks, render a chunk, merge chunks, render a
whole scene (the local render is the plan of one chunk, or K with --chunks).

A render of S samples per pixel with seed s splits into K chunks of ⌈S/K⌉ or ⌊S/K⌋ spp with distinct
derived seeds (``plan_chunks``). The image renders in tiles (row bands, ``Renderer.tiles``) whose samples
depend only on (chunk seed, tile, pass), so a chunk's tiles and a render's chunks can run in any order or
process and give the same sums. A chunk's sums are rounded to float32 once (``PixelSums.rounded``: what
its ``.npz`` partial stores) and the chunks' sums are added in float64 in chunk order, tile by tile, so a
local render (``render_scene``), a service job of one chunk and the merge of K uploaded partials
(``merge_chunks``) write bitwise-identical images for the same plan; the unsplit render is the K = 1
plan. Nothing holds more than one tile of per-pixel sums: image.exr and variance.exr are written band by
band (``hgcore.artifacts.images.image_set_writer``), partials are streamed in and out by rows. A
noise-target render, whose error is a statistic over all pixels (``hgcore.noise_target``), keeps its
running sums between rounds on disk (``hgcore.artifacts.running_sums``) and measures the error row band
by row band; only a render with ``on_chunk`` previews (tev) reads the whole image's sums back at once.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hgcore import noise_target
from hgcore.artifacts.images import IMAGE_FILES, image_set_writer, write_summary
from hgcore.artifacts.layout import SUMMARY_JSON, BandLayout
from hgcore.artifacts.pixel_sums import PartialReader, PixelSums, iter_merged_rows, partial_writer
from hgcore.artifacts.running_sums import RunningSums
from hgcore.errors import InputError
from hgcore.noise_target import ImageErrors, NoiseTarget
from hgcore.settings import SceneLimits
from schemas.scene import ABSOLUTE_MAX_SPP, Scene
from schemas.validation import with_film_overrides
from worker.mitsuba_setup import configured_mitsuba
from worker.render.renderer import Renderer, tile_bands
from worker.render.scene_compiler import SceneCompiler
from worker.render.wavelength_sampling import sampling_mode

ProgressCallback = Callable[[float], None]
RoundCallback = Callable[[RunningSums, ImageErrors, list[dict[str, Any]]], None]
"""``on_round(running, errors, rounds)`` of a noise-target render: the running sums of the rounds so far
(read them a row band at a time), their errors and each round's ``{"spp", "seconds", "rel_error"}``
(``hgcore.noise_target.summary_block``'s ``rounds``)."""


@dataclass(frozen=True)
class ChunkSpec:
    index: int
    spp: int
    seed: int


def chunk_seed(base_seed: int, index: int) -> int:
    """The seed of chunk ``index`` of a render with ``base_seed`` (chunk 0 keeps the base seed)."""
    return (base_seed + 0x632BE5AB * index) & 0xFFFFFFFF


def plan_chunks(total_spp: int, chunk_count: int, base_seed: int) -> list[ChunkSpec]:
    """Split ``total_spp`` into ``chunk_count`` chunks (≥ 1 spp each) with distinct seeds."""
    if total_spp < 1:
        raise InputError(f"spp: must be at least 1, got {total_spp}")
    if chunk_count < 1:
        raise InputError(f"chunks: must be at least 1, got {chunk_count}")
    chunk_count = min(chunk_count, total_spp)
    base, extra = divmod(total_spp, chunk_count)
    return [
        ChunkSpec(index, base + (1 if index < extra else 0), chunk_seed(base_seed, index))
        for index in range(chunk_count)
    ]


_renderers: dict[str, Renderer] = {}


def renderer_for(
    scene: Scene, bundle_dir: Path | None = None, *, limits: SceneLimits | None = None
) -> Renderer:
    """A Renderer for ``scene``, reused within a process for identical scenes (load once, kernels cached).

    ``limits``: the process's settings, which the compile checks the scene's images against. Every
    production caller passes its own (``tests/test_layering.py`` checks it); None reads ``SceneLimits()``
    from the environment, for tests and benchmarks (which also measure older trees without the argument).
    """
    limits = limits if limits is not None else SceneLimits()
    key = scene.model_dump_json(by_alias=True) + str(bundle_dir) + limits.model_dump_json()
    if key not in _renderers:
        compiled = SceneCompiler(configured_mitsuba(), bundle_dir, limits=limits).compile(scene)
        _renderers.clear()  # one scene at a time keeps worker memory bounded
        _renderers[key] = Renderer(compiled)
    return _renderers[key]


def film_bands(scene: Scene) -> BandLayout:
    film = scene.film
    return BandLayout(film.wavelength_min_nm, film.wavelength_max_nm, film.bands)


class _Progress:
    """Progress of a render over ``total`` units (samples) reported as a fraction in [0, 1], never
    decreasing (a noise-target render raises ``total`` when it plans another round)."""

    def __init__(self, callback: ProgressCallback | None, total: float) -> None:
        self.callback, self.total, self.done = callback, max(total, 1.0), 0.0
        self.reported = 0.0

    def part(self, units: float) -> ProgressCallback:
        """A callback for a part of ``units`` units, starting where the parts before it ended."""
        start = self.done
        self.done += units

        def report(fraction: float) -> None:
            self.reported = max(self.reported, min(1.0, (start + fraction * units) / self.total))
            if self.callback is not None:
                self.callback(self.reported)

        return report


class RenderTimer:
    """Seconds spent rendering (tiles and passes), apart from writing files between tiles."""

    def __init__(self) -> None:
        self.seconds = 0.0


def render_tiles(
    renderer: Renderer,
    chunks: Sequence[ChunkSpec],
    *,
    progress: ProgressCallback | None = None,
    should_stop: Callable[[], bool] | None = None,
    timer: RenderTimer | None = None,
) -> Iterator[PixelSums]:
    """The image's sums tile by tile (top to bottom): each tile's chunks rendered, rounded and added in
    chunk order. Only the tile being yielded is held."""
    tiles = renderer.tiles()
    tracker = _Progress(progress, sum(c.spp for c in chunks) * renderer.width * renderer.height)
    for index, (y0, y1) in enumerate(tiles):
        total: PixelSums | None = None
        for chunk in chunks:
            started = time.perf_counter()
            report = tracker.part(chunk.spp * (y1 - y0) * renderer.width)
            sums = renderer.render_tile_sums(index, chunk.spp, chunk.seed, report, should_stop).rounded()
            total = sums if total is None else total.add(sums)
            if timer is not None:
                timer.seconds += time.perf_counter() - started
        assert total is not None
        yield total


def render_chunk(
    scene: Scene,
    chunk: ChunkSpec,
    out_path: Path,
    *,
    progress: ProgressCallback | None = None,
    should_stop: Callable[[], bool] | None = None,
    bundle_dir: Path | None = None,
    limits: SceneLimits | None = None,
) -> dict[str, Any]:
    """Render one chunk and stream its per-pixel sums, tile by tile, to ``out_path`` (.npz, atomic).
    Returns its index, spp, samples, seconds (scene load included) and samples per second. ``limits``:
    the process's settings (``renderer_for``)."""
    start = time.perf_counter()
    renderer = renderer_for(scene, bundle_dir, limits=limits)
    with partial_writer(out_path, renderer.width, renderer.height, scene.film.bands) as writer:
        for sums in render_tiles(renderer, [chunk], progress=progress, should_stop=should_stop):
            writer.write_rows(sums)
        seconds = time.perf_counter() - start
        writer.finish(chunk.spp, seconds, chunk.index, chunk.seed)
    samples = chunk.spp * renderer.width * renderer.height
    return {
        "index": chunk.index,
        "spp": chunk.spp,
        "samples": samples,
        "seconds": seconds,
        "samples_per_second": samples / seconds if seconds > 0 else None,
    }


def merge_chunks(
    scene: Scene,
    chunk_paths: Sequence[Path],
    out_dir: Path,
    *,
    extra_summary: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Add the chunks' partials (in chunk-index order), row band by row band, and write image.exr,
    variance.exr, preview.png and summary.json."""
    if not chunk_paths:
        raise InputError("chunk_paths: at least one chunk is needed")
    readers = sorted((PartialReader(Path(path)) for path in chunk_paths), key=lambda r: r.chunk_index)
    width, height = scene.film.width, scene.film.height
    if any((r.width, r.height, r.band_count) != (width, height, scene.film.bands) for r in readers):
        raise InputError("chunk_paths: a partial's size or bands differ from the scene's film")
    return write_merged(
        scene,
        iter_merged_rows(readers, tile_bands(width, height)),
        out_dir,
        chunks=len(readers),
        render_seconds=lambda: sum(r.seconds for r in readers),
        extra_summary=extra_summary,
    )


def write_merged(
    scene: Scene,
    row_bands: Iterable[PixelSums],
    out_dir: Path,
    *,
    chunks: int,
    render_seconds: Callable[[], float],
    extra_summary: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Write image.exr, variance.exr, preview.png and summary.json from the merged sums, row band by row
    band (top to bottom). ``render_seconds()``: the render time, read once every band was consumed."""
    film = scene.film
    out_dir = Path(out_dir)
    sample_count = 0
    with image_set_writer(out_dir, film_bands(scene), film.width, film.height) as writer:
        for sums in row_bands:
            sample_count = sums.sample_count
            writer.write_rows(sums)
    seconds = render_seconds()
    samples = sample_count * film.width * film.height
    summary = {
        "scene": scene.name,
        "width": film.width,
        "height": film.height,
        "spp": sample_count,
        "bands": film.bands,
        "band_centers_nm": film_bands(scene).centers_nm.tolist(),
        "modes": film.modes,
        "max_depth": film.max_depth,
        "integrator": film.integrator,
        "wavelength_sampling": sampling_mode(scene),  # auto resolved
        "chunks": chunks,
        "variant": configured_mitsuba().variant(),
        "render_seconds": seconds,
        "samples": samples,
        "samples_per_second": samples / seconds if seconds > 0 else None,
        "coherence": writer.coherence_statistics(),
        "files": [*IMAGE_FILES, SUMMARY_JSON],
        **(extra_summary or {}),
    }
    write_summary(out_dir, summary)
    return summary


def render_to_dir(
    scene: Scene,
    out_dir: Path,
    plan: Sequence[ChunkSpec],
    *,
    progress: ProgressCallback | None = None,
    should_stop: Callable[[], bool] | None = None,
    bundle_dir: Path | None = None,
    limits: SceneLimits | None = None,
    on_chunk: Callable[[PixelSums], None] | None = None,
    target: NoiseTarget | None = None,
    on_round: RoundCallback | None = None,
    extra_summary: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Render ``plan``'s chunks in this process and write the final artifacts to ``out_dir``.

    Streams tile by tile (every chunk of a tile, then the next tile) unless ``on_chunk(sums)`` wants the
    running sum of the chunks finished so far after each one (previews) or a noise ``target`` adds chunks
    (rounds) until it is met. Those two render chunk by chunk into ``RunningSums`` on disk, one tile in
    memory, which gives the same bits (the same rounded chunk tile sums added in the same order). With a
    ``target``, ``on_round(running, errors, rounds)`` is called after each round that another round
    follows (a running job's preview; the last round's sums become the final artifacts instead); it only
    reads the sums, so the result is the same with or without it. ``limits``: the process's settings
    (``renderer_for``)."""
    load_started = time.perf_counter()
    renderer = renderer_for(scene, bundle_dir, limits=limits)
    load_seconds = time.perf_counter() - load_started  # counted as render time, as a chunk's is
    if on_chunk is None and target is None:
        timer = RenderTimer()
        timer.seconds = load_seconds
        tiles = render_tiles(renderer, plan, progress=progress, should_stop=should_stop, timer=timer)
        return write_merged(
            scene,
            tiles,
            out_dir,
            chunks=len(plan),
            render_seconds=lambda: timer.seconds,
            extra_summary=extra_summary,
        )
    tracker = _Progress(progress, sum(c.spp for c in plan))
    chunks = list(plan)
    rounds: list[dict[str, Any]] = []
    render_seconds = load_seconds
    started = time.perf_counter()
    band_count = scene.film.bands
    tiles = renderer.tiles()
    with RunningSums(renderer.width, renderer.height, band_count) as running:
        index = 0
        while index < len(chunks):
            chunk = chunks[index]
            # ---- add the chunk to the running sums, tile by tile; measure the error at a round's end
            round_ends = target is not None and index == len(chunks) - 1
            errors = ImageErrors()
            report = tracker.part(chunk.spp)
            for tile_index, (y0, _) in enumerate(tiles):

                def tile_progress(
                    fraction: float, tile_index: int = tile_index, report: ProgressCallback = report
                ) -> None:
                    report((tile_index + fraction) / len(tiles))

                tile_started = time.perf_counter()  # render time: the tile, not the bookkeeping after it
                sums = renderer.render_tile_sums(
                    tile_index, chunk.spp, chunk.seed, tile_progress, should_stop
                ).rounded()
                render_seconds += time.perf_counter() - tile_started
                rows = running.add_rows(y0, sums)
                if round_ends:
                    errors.add(rows)
                del sums, rows  # a tile's tables must not live on while the next tile renders
            running.finish_chunk(chunk.spp)
            if on_chunk is not None:
                on_chunk(running.whole())
            index += 1
            if not round_ends:
                continue
            # ---- plan the next round, or stop
            assert target is not None
            error = errors.achieved(target)
            rounds.append({"spp": running.sample_count, "seconds": render_seconds, "rel_error": error})
            more = noise_target.next_round_spp(
                target,
                running.sample_count,
                error,
                render_seconds,
                time.perf_counter() - started,
                ABSOLUTE_MAX_SPP,
            )
            if more > 0:
                if on_round is not None:
                    on_round(running, errors, rounds)
                chunks.append(ChunkSpec(len(chunks), more, chunk_seed(scene.film.seed, len(chunks))))
                # The total is now a prediction: progress runs over the samples planned so far.
                tracker.total += more
        extra = dict(extra_summary or {})
        if target is not None:
            reason = noise_target.stop_reason(
                target, rounds[-1]["rel_error"], running.sample_count, ABSOLUTE_MAX_SPP
            )
            extra["noise_target"] = noise_target.summary_block(target, errors, rounds, reason)
        return write_merged(
            scene,
            running.row_bands(tiles),
            out_dir,
            chunks=len(chunks),
            render_seconds=lambda: render_seconds,
            extra_summary=extra,
        )


def render_scene(
    scene: Scene,
    out_dir: Path,
    *,
    spp: int | None = None,
    seed: int | None = None,
    modes: int | None = None,
    integrator: str | None = None,
    chunks: int = 1,
    progress: ProgressCallback | None = None,
    bundle_dir: Path | None = None,
    limits: SceneLimits | None = None,
    on_chunk: Callable[[PixelSums], None] | None = None,
    target: NoiseTarget | None = None,
) -> dict[str, Any]:
    """Render locally and write the final artifacts to ``out_dir`` (``render_to_dir``). With a noise
    ``target``, ``spp`` (or film.spp) is the first round's. ``spp``, ``seed``, ``modes`` and
    ``integrator`` override the film's (``schemas.with_film_overrides``), checked against ``limits``, the
    process's settings, which the compile also checks the images against (``renderer_for``)."""
    limits = limits if limits is not None else SceneLimits()
    scene = with_film_overrides(scene, limits, spp=spp, seed=seed, modes=modes, integrator=integrator)
    plan = plan_chunks(scene.film.spp, chunks, scene.film.seed)
    return render_to_dir(
        scene,
        Path(out_dir),
        plan,
        progress=progress,
        bundle_dir=bundle_dir,
        limits=limits,
        on_chunk=on_chunk,
        target=target,
    )
