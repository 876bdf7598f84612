"""Tiled rendering: bitwise equality of every way a render's tiles and chunks can travel (tile-major in
one process, chunk-major with previews, chunk partials merged as the service does), row-streamed partials
and EXRs, and the tile plan itself."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

import worker.render.renderer as renderer_module
from hgcore.artifacts.exr import ArtifactFormatError, exr_scanline_writer, read_exr
from hgcore.artifacts.pixel_sums import (
    SUM_KEYS,
    PartialReader,
    PixelSums,
    partial_writer,
    read_partial,
    write_partial,
)
from hgcore.artifacts.running_sums import RunningSums
from hgcore.noise_target import ImageErrors
from schemas import validate_scene
from tests.integrator.scenes import D65_SPHERE_SOURCE, plane_under_source
from worker.render.chunks import merge_chunks, plan_chunks, render_chunk, render_scene, renderer_for
from worker.render.renderer import row_order, tile_rows, tile_seed


def all_channels(out_dir: Path) -> dict[str, np.ndarray]:
    image, variance = read_exr(out_dir / "image.exr"), read_exr(out_dir / "variance.exr")
    return {**image.channels, **{f"variance/{k}": v for k, v in variance.channels.items()}}


def assert_bitwise_equal(a: Path, b: Path) -> None:
    channels_a, channels_b = all_channels(a), all_channels(b)
    assert list(channels_a) == list(channels_b)
    differing = [name for name in channels_a if not np.array_equal(channels_a[name], channels_b[name])]
    assert differing == []


@pytest.fixture
def small_tiles(monkeypatch: pytest.MonkeyPatch) -> int:
    """Tiles of 3 rows on a 20-pixel-wide image: 7 tiles (the last one of 2 rows)."""
    monkeypatch.setattr(renderer_module, "TILE_PIXELS", 60)
    return 3


@pytest.fixture
def scene() -> dict:
    return plane_under_source(D65_SPHERE_SOURCE, size_px=20, spp=6)


def test_tile_plan_covers_the_image_in_row_bands(scene: dict, small_tiles: int) -> None:
    assert tile_rows(20, 20) == small_tiles
    assert tile_rows(1 << 20, 4) == 1  # never fewer than one row
    assert tile_rows(8, 4) == 4  # never more than the image
    tiles = renderer_for(validate_scene(scene)).tiles()
    assert tiles[0] == (0, 3) and tiles[-1] == (18, 20)
    assert all(a[1] == b[0] for a, b in itertools.pairwise(tiles))


def test_tile_major_chunk_major_and_merged_partials_are_bitwise_equal(
    scene: dict, small_tiles: int, tmp_path: Path
) -> None:
    tile_major = render_scene(validate_scene(scene), tmp_path / "tile_major", chunks=3)
    previews: list[int] = []
    render_scene(
        validate_scene(scene),
        tmp_path / "chunk_major",
        chunks=3,
        on_chunk=lambda s: previews.append(s.sample_count),
    )
    assert previews == [2, 4, 6]
    paths = []
    for chunk in plan_chunks(6, 3, scene["film"].get("seed", 0)):
        path = tmp_path / "partials" / f"{chunk.index}.npz"
        result = render_chunk(validate_scene(scene), chunk, path)
        assert result["samples"] == 2 * 20 * 20
        paths.append(path)
    merged = merge_chunks(
        validate_scene(scene), list(reversed(paths)), tmp_path / "merged"
    )  # order: by chunk index
    assert tile_major["spp"] == merged["spp"] == 6
    assert_bitwise_equal(tmp_path / "tile_major", tmp_path / "chunk_major")
    assert_bitwise_equal(tmp_path / "tile_major", tmp_path / "merged")
    assert tile_major["coherence"] == merged["coherence"]


def test_tiles_render_distinct_samples_with_the_same_expectation(
    scene: dict, small_tiles: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Tiles have their own seeds; the image mean agrees with an untiled render within its MC error."""
    render_scene(validate_scene(scene), tmp_path / "tiled", spp=32)
    monkeypatch.setattr(renderer_module, "TILE_PIXELS", 1 << 18)
    render_scene(validate_scene(scene), tmp_path / "whole", spp=32)
    tiled, whole = all_channels(tmp_path / "tiled"), all_channels(tmp_path / "whole")
    band = next(name for name in tiled if name.startswith("S0."))
    assert not np.array_equal(tiled[band][3:], whole[band][3:])  # rows below the first tile differ
    # Tile 0 keeps the chunk's own seed (an image of one tile renders with the chunk's seed); its rows are
    # not the whole image's first rows bitwise, since a pass orders a tile's rows by the tile's height
    # (``renderer.row_order``).
    assert tile_seed(1234, 0) == 1234 and tile_seed(1234, 1) != 1234
    # Standard error of the image mean: √(Σ variance of the pixel means)/P, for each render.
    pixels = tiled[band].size
    sigma = np.sqrt(tiled[f"variance/{band}"].sum() + whole[f"variance/{band}"].sum()) / pixels
    assert abs(tiled[band].mean() - whole[band].mean()) < 4 * sigma


def test_partials_stream_by_rows_and_round_like_in_memory_chunks(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    shape = (7, 5)
    sums = random_sums(rng, 3, shape, 4)
    path = tmp_path / "p.npz"
    with partial_writer(path, 5, 7, 4) as writer:
        writer.write_rows(sums.row_slice(0, 4))
        writer.write_rows(sums.row_slice(4, 7))
        writer.finish(3, 1.25, 2, 99)
    reader = PartialReader(path)
    assert (reader.sample_count, reader.seconds, reader.chunk_index, reader.seed) == (3, 1.25, 2, 99)
    rounded = sums.rounded()
    assert np.array_equal(reader.rows(2, 6).bands_sq, rounded.bands_sq[2:6])
    assert np.array_equal(reader.rows(6, 7).values["vcz_dyz"], rounded.values["vcz_dyz"][6:7])
    assert not np.array_equal(rounded.bands, sums.bands)  # float32 rounding did happen
    write_partial(tmp_path / "q.npz", sums, 1.0, 0, 0)
    whole, seconds = read_partial(tmp_path / "q.npz")
    assert seconds == 1.0 and np.array_equal(whole.values["depth"], rounded.values["depth"])
    write_partial(tmp_path / "r.npz", sums, 1.0, 0, 0, rows_per_write=3)  # 3 + 3 + 1 rows
    banded, _ = read_partial(tmp_path / "r.npz")
    assert np.array_equal(banded.table(), whole.table())
    assert sorted(np.load(path).files) == [
        "band_count",
        "chunk_index",
        "sample_count",
        "seconds",
        "seed",
        "sums",
    ]


def test_an_unfinished_partial_or_exr_leaves_no_file(tmp_path: Path) -> None:
    sums = PixelSums(1, np.ones((2, 3, 1)), np.ones((2, 3, 1)), {k: np.ones((2, 3)) for k in SUM_KEYS})
    with pytest.raises(ValueError, match="rows written"), partial_writer(tmp_path / "p.npz", 3, 4, 1) as w:
        w.write_rows(sums)
        w.finish(1, 0.0, 0, 0)  # 2 of 4 rows
    with (
        pytest.raises(ArtifactFormatError, match="in order"),
        exr_scanline_writer(tmp_path / "x.exr", 3, 4, ["R"], {}) as exr,
    ):
        exr.write_rows(2, [np.zeros((2, 3))])  # rows 0-1 skipped
    with (
        pytest.raises(ArtifactFormatError, match="cannot be written"),
        exr_scanline_writer(tmp_path / "y.exr", 3, 4, ["R"], {}) as exr,
    ):
        exr.write_rows(0, [np.zeros((2, 3))])  # the block ends with rows 2-3 missing
    assert list(tmp_path.iterdir()) == []


def random_sums(rng: np.random.Generator, sample_count: int, shape: tuple[int, int], bands: int) -> PixelSums:
    return PixelSums(
        sample_count,
        rng.random((*shape, bands)) * 1e3,
        rng.random((*shape, bands)) * 1e6,
        {key: rng.random(shape) for key in SUM_KEYS},
    )


def test_running_sums_on_disk_add_chunks_bitwise_as_whole_images_do() -> None:
    """Three chunks added row band by row band into ``RunningSums`` equal ``PixelSums.add`` of the whole
    images to the bit (same float64 additions, same order), and the file keeps every column apart."""
    rng = np.random.default_rng(7)
    chunks = [random_sums(rng, spp, (7, 5), 4) for spp in (2, 3, 5)]
    bands = [(0, 3), (3, 6), (6, 7)]
    with RunningSums(5, 7, 4) as running:
        for chunk in chunks:
            returned = [running.add_rows(y0, chunk.row_slice(y0, y1)) for y0, y1 in bands]
            running.finish_chunk(chunk.sample_count)
        expected = chunks[0].add(chunks[1]).add(chunks[2])
        assert running.sample_count == expected.sample_count == 10
        stored = PixelSums.concatenate(list(running.row_bands(bands)))
        assert np.array_equal(stored.table(), expected.table())  # float32 view of the whole table
        assert np.array_equal(stored.bands, expected.bands) and np.array_equal(
            stored.bands_sq, expected.bands_sq
        )
        assert all(np.array_equal(stored.values[k], expected.values[k]) for k in SUM_KEYS)
        assert np.array_equal(PixelSums.concatenate(returned).bands, expected.bands)  # what add_rows returned
        assert np.array_equal(running.whole().values["luminance"], expected.values["luminance"])
        with pytest.raises(ValueError, match="not stored"):
            running.rows(6, 9)


def test_image_errors_from_row_bands_equal_those_of_the_whole_image() -> None:
    """The noise-target errors accumulated band by band (what a streamed render measures) are those of
    the whole image: the luminance quantile exactly, the band-mean errors to float64 rounding."""
    rng = np.random.default_rng(8)
    whole = random_sums(rng, 4, (9, 6), 3)
    whole.values["luminance"][0, :2] = 0.0  # unlit pixels are left out of the quantile
    by_bands = ImageErrors.of(whole.row_slice(y0, min(y0 + 4, 9)) for y0 in range(0, 9, 4))
    at_once = ImageErrors.of([whole])
    np.testing.assert_allclose(by_bands.band_rel_errors(), at_once.band_rel_errors(), rtol=1e-14)
    assert by_bands.luminance_rel_error(0.9) == at_once.luminance_rel_error(0.9)
    # and both are the closed form of the module docstring, written out here independently
    mean = whole.bands / 4
    variance = np.maximum(whole.bands_sq / 4 - mean**2, 0) / 4
    expected = np.sqrt(variance.sum(axis=(0, 1))) / mean.sum(axis=(0, 1))
    np.testing.assert_allclose(at_once.band_rel_errors(), expected, rtol=1e-14)
    assert by_bands.pixels == 54 and by_bands.sample_count == 4


@pytest.mark.parametrize("rows", [1, 2, 3, 16, 60, 128, 1000])
def test_row_order_is_a_permutation_whose_runs_cover_the_tile_evenly(rows: int) -> None:
    order = row_order(rows)
    assert sorted(order.tolist()) == list(range(rows))
    if rows >= 16:
        # Each half of the slots (one core's block on two cores) has rows from every quarter of the tile.
        for half in (order[: rows // 2], order[rows // 2 :]):
            assert sorted(set(half * 4 // rows)) == [0, 1, 2, 3]
            assert abs(half.mean() - (rows - 1) / 2) < 0.1 * rows
