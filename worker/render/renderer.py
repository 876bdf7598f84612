"""Runs ``hg_path`` over the image and reduces samples into per-pixel sums (deterministically).

The image renders in tiles (row bands of ``tile_rows`` rows, ~``TILE_PIXELS`` pixels), so a render holds
one tile's sums, not the image's. Within a tile, each lane traces ``samples_per_lane`` samples of one
pixel one after another and sums their outputs in registers; a pixel's lanes are adjacent (wavefront
index = pixel·lanes + lane) and reduce with ``dr.block_sum``. Sums therefore do not depend on thread
scheduling: the same scene, spp and seed give bitwise-identical output, which scatter-based (atomic) film
accumulation would not. Passes bound the samples per pass (``MAX_WAVEFRONT``); sums are accumulated in
float64 on the host in one (pixels, columns) table. A chunk is a set of passes with its own seed per tile;
chunks merge by adding sums.

Kernel compilation: Dr.Jit caches compiled kernels by the hash of their IR (in memory and on disk under
``~/.drjit``), so a second render of a scene with the same structure and constants skips compilation.

Frozen passes: a pass is a frozen function (``dr.freeze``): its first call traces the path loop (~10 ms
of Python per pass, 2 % of a 128² × 64 spp Cornell box's CPU time) and records the kernels it launches;
later passes of the same shape (rows, spp) replay them with the new seed. A recording names what its
kernels read: the scene, the seed and the tile's first row (opaque arguments), every table of the
integrator, materials and wavelength sampler (``_pass_state``, each owner's ``kernel_tables``), and the
Python settings the trace depends on (``_trace_settings``). Each pass shape (rows, spp) under each
settings tuple has a frozen function of its own (``_frozen_pass_for``): Dr.Jit 1.5's own comparison of the
Python values in its key missed a change of ``max_depth`` from 8 to 2, and in the full test suite replayed
another shape's recording for a noise-target round (a round's image differed from the same chunks'). Replays
are bitwise the traced passes
(tests/integrator/test_frozen_passes.py); a scene whose kernels read an array no owner names cannot be
recorded, and renders unfrozen (with a warning) rather than not at all.
"""

from __future__ import annotations

import contextlib
import gc
import logging
import math
from collections import OrderedDict
from collections.abc import Callable, Iterator
from typing import Any

import drjit as dr
import numpy as np

from hgcore.artifacts.pixel_sums import SUM_KEYS, PixelSums, column_count
from hgcore.colour import image_xyz_weights
from hgcore.optics.sources import source_coefficients
from worker.mitsuba_setup import configured_mitsuba
from worker.render.bsdfs import MaterialKernels
from worker.render.emitters import CylinderModes, EmitterKind
from worker.render.integrator import RenderContext, register
from worker.render.rlt import integrator_class
from worker.render.scene_compiler import CompiledScene
from worker.render.spectral import cie1931_table, cie1931_xyz
from worker.render.textures import TextureKernels
from worker.render.wavelength_sampling import WavelengthSampler, lane_weights, scene_density

log = logging.getLogger(__name__)

MAX_WAVEFRONT = 1 << 20  # samples per pass (their lanes' ~60 float32 sums stay in memory until reduced)
SAMPLES_PER_LANE = 16
"""Samples a lane traces in sequence (``samples_per_lane``). Summing them in the megakernel's registers
stores and reduces 1/16 of the per-sample outputs (60 float32 columns: 18 of the 330 ms of a 128² × 64 spp
Cornell box went to storing and block-summing them per sample); a pixel's 16-lane packets still trace
that pixel's samples (its camera rays stay coherent), which a loop over all of a pixel's samples in one
lane would give up (+3 % megakernel time, measured)."""
MIN_WAVEFRONT_LANES = 2
"""Fewest lanes a pass launches (``_pass_columns``): Dr.Jit treats size-1 arrays like literals."""
FROZEN_PASS_SHAPES = 4
"""Recordings a renderer keeps (least recently used dropped): a render has at most two tile heights and
two pass sizes (the full one and the remainder)."""
TILE_PIXELS = 1 << 18
"""Pixels per tile (row band), at least one row. A tile's float64 sums (2B + 28 columns: 188 MiB at 32
bands) are all the per-pixel state a render holds; 4 spp per pass at 1 M samples keeps passes full."""


def tile_rows(width: int, height: int) -> int:
    """Rows per tile: ``TILE_PIXELS`` / width, at least 1, at most the image. A function of the image size
    only, so a scene's tiles (and so its samples) are the same on every machine and in every process."""
    return max(1, min(height, TILE_PIXELS // max(width, 1)))


def tile_bands(width: int, height: int) -> list[tuple[int, int]]:
    """The image's tiles: row bands ``[y0, y1)`` of ``tile_rows(width, height)`` rows, top to bottom."""
    rows = tile_rows(width, height)
    return [(y0, min(y0 + rows, height)) for y0 in range(0, height, rows)]


def tile_seed(chunk_seed: int, tile_index: int) -> int:
    """The seed of a chunk's tile: the chunk's own for tile 0 (an image of one tile renders with the chunk's
    seed), distinct 32-bit mixes for the others."""
    if tile_index == 0:
        return chunk_seed
    return (chunk_seed * 0x2C1B3C6D + tile_index * 0x297A2D39 + 0x7ED55D16) & 0xFFFFFFFF


def samples_per_lane(spp: int) -> int:
    """Samples each lane of a pass of ``spp`` samples per pixel traces: the largest power of two that
    divides ``spp``, at most ``SAMPLES_PER_LANE``, so every lane of a pixel traces as many."""
    count = 1
    while count < SAMPLES_PER_LANE and spp % (2 * count) == 0:
        count *= 2
    return count


def row_stride(rows: int) -> int:
    """The stride of ``row_order``: the integer nearest rows/φ (φ the golden ratio) that is coprime with
    ``rows``, so that k ↦ k·stride mod rows is a permutation."""
    target = rows / ((1.0 + math.sqrt(5.0)) / 2.0)
    for offset in range(rows):
        for stride in (round(target) - offset, round(target) + offset):
            if 1 <= stride < rows and math.gcd(stride, rows) == 1:
                return stride
    return 1  # rows ≤ 2


def row_order(rows: int) -> np.ndarray:
    """The order in which a pass traces a tile's ``rows`` rows: slot k traces row k·``row_stride`` mod
    rows. Why: Dr.Jit's LLVM backend splits a wavefront of up to 2 × 16 384 lanes per core into one
    contiguous block per core (``LLVMThreadState::launch``), so in image order one core traced the top of a
    128² × 64 spp tile and the other its bottom, and each of 16 cores would trace a sixteenth of the image,
    of different costs. With a golden-ratio stride every run of consecutive slots covers the tile's rows
    evenly (a Weyl sequence), whatever the number of blocks; rows stay whole, so a packet's camera rays
    stay coherent. (On two cores the halves were nearly balanced already: busy 98.6 % → 99.3 %.)"""
    return np.arange(rows) * row_stride(rows) % rows


def pass_seed(chunk_seed: int, pass_index: int) -> int:
    """A 32-bit seed per pass, distinct across chunks and passes (deterministic)."""
    return (chunk_seed * 0x9E3779B1 + pass_index * 0x85EBCA77 + 0x165667B1) & 0xFFFFFFFF


class Renderer:
    """One loaded Mitsuba scene plus the ``hg_path`` integrator attached to its tables."""

    def __init__(self, compiled: CompiledScene) -> None:
        self.mi = mi = configured_mitsuba()
        register()
        self.compiled = compiled
        # optimize=False: merged shapes would lose the ids that map them to materials.
        self.scene = mi.load_dict(compiled.mitsuba_dict, optimize=False)
        self.sensor = self.scene.sensors()[0]
        self.width, self.height = compiled.scene.film.width, compiled.scene.film.height
        # film.integrator: hg_path (partially coherent, PLT) or rlt (the radiometric baseline).
        self.integrator = integrator_class(compiled.scene.film.integrator)(mi.Properties())
        self.integrator.max_depth = compiled.scene.film.max_depth
        self.integrator.attach(self._context())
        self.lens = None if compiled.lens is None else compiled.lens.on_device(mi)
        # film.wavelength_sampling: uniform, or the scene's importance density (tabulated once here).
        self.wavelengths = WavelengthSampler(
            mi, compiled.bands, scene_density(compiled.scene, compiled.bands)
        )
        # Y of a sample from its band values with the weights image.exr's Y has of the band means, so that
        # the per-sample luminance sums give variance.exr's Y in image.exr's units.
        self._band_luminance = image_xyz_weights(compiled.bands.edges_nm)[:, 1].tolist()
        #: whether passes replay recorded kernels (module docstring, "Frozen passes")
        self.frozen_passes = True
        # One frozen function per pass shape and settings (``_frozen_pass_for``), the most recent last.
        self._frozen_passes: OrderedDict[tuple[Any, ...], Any] = OrderedDict()
        self._frozen_pass: Any = None  # the last pass's (tests read its recordings)

    def _context(self) -> RenderContext:
        mi = self.mi
        compiled = self.compiled
        shapes = list(self.scene.shapes())
        shape_ids = [int(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(shape))[0]) for shape in shapes]
        shape_material = np.full(
            max(shape_ids) + 1, len(compiled.material_table.records) - 1, dtype=np.uint32
        )
        emitter_ids: dict[int, int] = {}
        for shape, registry_id in zip(shapes, shape_ids, strict=True):
            key = shape.id()
            shape_material[registry_id] = compiled.shape_materials[key]
            if key in compiled.emitter_records:
                emitter_id = int(dr.reinterpret_array(mi.UInt32, mi.EmitterPtr(shape.emitter()))[0])
                emitter_ids[emitter_id] = compiled.emitter_records[key]
        environment = self.scene.environment()
        if environment is not None and compiled.environment_record is not None:
            emitter_ids[int(dr.reinterpret_array(mi.UInt32, mi.EmitterPtr(environment))[0])] = (
                compiled.environment_record
            )
        emitter_index = np.zeros(max(emitter_ids, default=0) + 1, dtype=np.uint32)
        for registry_id, record in emitter_ids.items():
            emitter_index[registry_id] = record
        right, up = self._screen_axes()
        camera_right, camera_up = mi.Vector3f(*right), mi.Vector3f(*up)
        # Opaque: as literals their order in the IR changed between the first and later traces, so the first
        # render compiled a kernel that no later render reused.
        camera_position = mi.Point3f(*self.sensor.world_transform().translation())
        dr.make_opaque(camera_right, camera_up, camera_position)
        kinds = {record.kind for record in compiled.emitter_table.records}
        return RenderContext(
            bands=compiled.bands,
            material_table=compiled.material_table,
            material_flat=mi.Float(compiled.material_table.flat()),
            spectra_flat=mi.Float(compiled.spectral_table.flat()),
            shape_material=mi.UInt32(shape_material),
            emitter_flat=mi.Float(compiled.emitter_table.flat()),
            emitter_index=mi.UInt32(emitter_index),
            emitter_kinds=kinds,
            black_material=len(compiled.material_table.records) - 1,
            disk_coefficients=source_coefficients("disk", compiled.scene.film.modes),
            rect_coefficients=source_coefficients("rect", compiled.scene.film.modes),
            rect_sources=bool(kinds & {EmitterKind.RECTANGLE, EmitterKind.CYLINDER}),
            cylinder_modes=CylinderModes.for_scene(mi, kinds, compiled.scene.film.modes),
            camera_right=camera_right,
            camera_up=camera_up,
            camera_position=camera_position,
            cie1931=cie1931_table(mi),
            textures=None if compiled.texture_table is None else TextureKernels(mi, compiled.texture_table),
        )

    def _environment_vcz(self, result: Any) -> tuple[Any, Any]:
        """(weight, direction) of environment light by NEE at the first vertex, or (None, None) in scenes
        without an environment (nothing traced)."""
        if EmitterKind.ENVIRONMENT not in self.integrator.context.emitter_kinds:
            return None, None
        return result.vcz_direct_weight, result.vcz_direct_direction

    def _screen_axes(self) -> tuple[list[float], list[float]]:
        """World directions of the image's +x (right) and up, from rays through the image centre."""
        mi = self.mi
        positions = mi.Point2f([0.5, 0.51, 0.5], [0.5, 0.5, 0.49])
        ray, _ = self.sensor.sample_ray(0.0, mi.Float(0.5), positions, mi.Point2f(0.5))
        d = np.array(ray.d)
        right = d[:, 1] - d[:, 0]
        up = d[:, 2] - d[:, 0]
        right -= np.dot(right, d[:, 0]) * d[:, 0]
        up -= np.dot(up, d[:, 0]) * d[:, 0]
        return (right / np.linalg.norm(right)).tolist(), (up / np.linalg.norm(up)).tolist()

    def tiles(self) -> list[tuple[int, int]]:
        """The image's tiles (``tile_bands``)."""
        return tile_bands(self.width, self.height)

    def render_sums(
        self,
        spp: int,
        seed: int,
        progress: Callable[[float], None] | None = None,
        should_stop: Callable[[], bool] | None = None,
    ) -> PixelSums:
        """Per-pixel sums of the whole image (every tile, stacked): ``spp`` samples per pixel with ``seed``;
        ``RenderCanceledError`` on stop. Memory ∝ the image: large renders stream ``render_tile_sums``."""
        tiles = self.tiles()
        parts = []
        for index in range(len(tiles)):

            def tile_progress(fraction: float, index: int = index) -> None:
                if progress is not None:
                    progress((index + fraction) / len(tiles))

            parts.append(self.render_tile_sums(index, spp, seed, tile_progress, should_stop))
        return PixelSums.concatenate(parts)

    def render_tile_sums(
        self,
        tile_index: int,
        spp: int,
        seed: int,
        progress: Callable[[float], None] | None = None,
        should_stop: Callable[[], bool] | None = None,
    ) -> PixelSums:
        """Per-pixel sums of tile ``tile_index`` (rows ``self.tiles()[tile_index]``), ``spp`` samples per
        pixel. The tile's samples depend only on (``seed``, tile, pass), never on which other tiles or
        chunks render in the same process, so tiles and chunks can run in any order or process."""
        y0, y1 = self.tiles()[tile_index]
        pixels = (y1 - y0) * self.width
        spp_per_pass = max(1, min(spp, MAX_WAVEFRONT // max(pixels, 1)))
        seed = tile_seed(seed, tile_index)
        # One float64 (pixels, columns) running total on the host: a pass adds its columns in one NumPy
        # operation, where a scatter kernel per column and pass cost 64 % of a 1024² render's wall time.
        totals: np.ndarray | None = None
        done = 0
        pass_index = 0
        while done < spp:
            if should_stop is not None and should_stop():
                raise RenderCanceledError("render stopped on request")
            count = min(spp_per_pass, spp - done)
            launched = self._render_pass(y0, y1, count, pass_seed(seed, pass_index))
            done += count
            pass_index += 1
            # Reported when the pass is launched (Dr.Jit's LLVM backend runs it asynchronously), before
            # the host copy below waits for it: progress runs at most one pass ahead of finished work,
            # and a job shows that it renders as soon as its first pass starts, not a pass later.
            if progress is not None:
                progress(done / spp)
            columns = np.stack([np.asarray(column) for column in launched], axis=-1)
            if totals is None:
                totals = columns.astype(np.float64)
            else:
                totals += columns
        assert totals is not None
        # Passes trace the tile's rows in ``row_order``: put them back in image order.
        table = np.empty((y1 - y0, self.width, totals.shape[-1]))
        table[row_order(y1 - y0)] = totals.reshape(table.shape)
        return PixelSums.from_table(spp, self.compiled.bands.band_count, table)

    def _render_pass(self, y0: int, y1: int, spp: int, seed: int) -> list[Any]:
        """Launch one pass over rows [y0, y1): per-pixel float32 sums of ``spp`` samples, one Dr.Jit
        array per column (bands, bands², then ``SUM_KEYS``), being evaluated asynchronously. Frozen
        (module docstring) unless this scene's kernels could not be recorded."""
        mi = self.mi
        # Opaque: as literals the seed and the tile's first row would be part of the kernels' IR (and of
        # the recording), so that every pass and tile compiled (and recorded) its own copy.
        arguments = (self.scene, dr.opaque(mi.UInt32, seed), dr.opaque(mi.UInt32, y0), y1 - y0, spp)
        if self.frozen_passes:
            self._frozen_pass = self._frozen_pass_for(y1 - y0, spp)
            try:
                with _collector_paused():
                    return self._frozen_pass(*arguments)
            except RuntimeError as error:
                # Raised while recording, before any kernel ran: the traced pass below gives the same sums
                # (and raises again if the error was not the recording's).
                log.warning("render passes of this scene run unfrozen: %s", str(error).splitlines()[0])
                self.frozen_passes = False
        return self._pass_columns(*arguments)

    def _frozen_pass_for(self, rows: int, spp: int) -> Any:
        """The frozen pass of this shape (``rows``, ``spp``) under the current ``_trace_settings``: one
        frozen function per key, each recording only arguments whose Python values never change, so no
        replay depends on Dr.Jit's comparison of Python values (module docstring). At most
        ``FROZEN_PASS_SHAPES`` are kept, the least recently used dropped (outside any frozen call)."""
        key = (self._trace_settings(), rows, spp)
        frozen = self._frozen_passes.get(key)
        if frozen is None:
            frozen = self._frozen_passes[key] = self._new_frozen_pass()
            while len(self._frozen_passes) > FROZEN_PASS_SHAPES:
                self._frozen_passes.popitem(last=False)
        else:
            self._frozen_passes.move_to_end(key)
        return frozen

    def _new_frozen_pass(self) -> Any:
        """A frozen ``_pass_columns`` (module docstring, "Frozen passes") for the current settings."""
        return dr.freeze(self._pass_columns, state_fn=self._pass_state, limit=FROZEN_PASS_SHAPES)

    def _trace_settings(self) -> tuple[Any, ...]:
        """The Python settings a pass's trace depends on: a change needs a new recording."""
        integrator = self.integrator
        return (
            type(integrator).__qualname__,
            integrator.max_depth,
            integrator.rr_depth,
            integrator.plane_waves,
            MaterialKernels.symbolic_branches,
            SAMPLES_PER_LANE,
            self.width,
            self.height,
        )

    def _pass_state(self, *_: Any) -> tuple[list[Any], tuple[Any, ...]]:
        """What a frozen pass reads besides its arguments: the arrays its kernels gather from, and the
        Python settings its trace depends on (also checked by ``_render_pass`` itself)."""
        integrator = self.integrator
        tables = (
            integrator.context.kernel_tables()
            + integrator.kernels.kernel_tables()
            + self.wavelengths.kernel_tables()
            + ([] if self.lens is None else self.lens.kernel_tables())
        )
        return tables, self._trace_settings()

    def _pass_columns(self, scene: Any, seed: Any, first_row: Any, rows: int, spp: int) -> list[Any]:
        """The kernels of one pass (``_render_pass``; ``scene`` is ``self.scene``, an argument so that a
        frozen pass traverses it): ``spp`` samples per pixel of ``rows`` rows from row ``first_row``, the
        rows in ``row_order`` (row slot k of the wavefront traces row ``row_order(rows)[k]``)."""
        mi = self.mi
        width = self.width
        lane_samples = samples_per_lane(spp)
        lanes_per_pixel = spp // lane_samples
        wavefront = width * rows * lanes_per_pixel
        # A wavefront of one lane would make every array of the pass a size-1 array, which Dr.Jit treats
        # like a literal inside its symbolic loops (and then refuses the loop state that changes): pad it
        # to two lanes and drop the extra one below.
        lanes = max(wavefront, MIN_WAVEFRONT_LANES)
        index = dr.arange(mi.UInt32, lanes)
        # The pass's spp and the image size stay literals: divisions by them compile to multiply-shift
        # sequences, while opaque divisors made the megakernel ~5 % slower (bench_compare, Cornell 128²);
        # a new spp per pass compiles once (~0.3 s).
        slot_pixel = index // lanes_per_pixel
        row = (slot_pixel // width) * row_stride(rows) % rows
        sampler = mi.load_dict({"type": "independent"})
        sampler.seed(seed, lanes)
        pixel_x = mi.Float(slot_pixel % width)
        pixel_y = mi.Float(first_row + row)
        sums = self._lane_sums(sampler, pixel_x, pixel_y, lane_samples)
        # One launch of the path megakernel for every column (reducing them one by one would re-run the
        # whole path loop for each), then a block sum per column over the pixel's lanes.
        dr.eval(sums)
        if lanes > wavefront:
            kept = dr.arange(mi.UInt32, wavefront)
            sums = [dr.gather(mi.Float, column, kept) for column in sums]
            dr.eval(sums)
        if lanes_per_pixel > 1:
            sums = [dr.block_sum(column, lanes_per_pixel) for column in sums]
            dr.eval(sums)
        return sums

    def _lane_sums(self, sampler: Any, pixel_x: Any, pixel_y: Any, lane_samples: int) -> list[Any]:
        """Each lane's sums of ``lane_samples`` samples of its pixel (``_sample_columns``), traced in a
        symbolic loop whose state is the sums, the sample counter and the sampler.

        The loop is traced with ``OptimizeLoops`` off: the flag's search for unchanging state traces a
        loop body twice, and around the path loop (traced twice itself) that made four traces of the path
        (+9 ms a render). All of this loop's state changes, so it had nothing to find; the path loop
        inside keeps the optimisation."""
        mi = self.mi
        columns = column_count(self.compiled.bands.band_count)
        state = (mi.UInt32(0), [mi.Float(0.0) for _ in range(columns)], sampler)

        def body(count: Any, sums: list[Any], sampler: Any) -> tuple[Any, list[Any], Any]:
            with dr.scoped_set_flag(dr.JitFlag.OptimizeLoops, True):
                values = self._sample_columns(sampler, pixel_x, pixel_y)
            return count + 1, [total + value for total, value in zip(sums, values, strict=True)], sampler

        with dr.scoped_set_flag(dr.JitFlag.OptimizeLoops, False):
            _, sums, _ = dr.while_loop(state, lambda count, *_: count < lane_samples, body, label="samples")
        return sums

    def _sample_columns(self, sampler: Any, pixel_x: Any, pixel_y: Any) -> list[Any]:
        """One camera sample of the pixel at (``pixel_x``, ``pixel_y``): its per-sample columns (bands,
        bands², then ``SUM_KEYS``)."""
        mi = self.mi
        bands = self.compiled.bands
        width, height = self.width, self.height
        film_position = mi.Point2f(
            (pixel_x + sampler.next_1d()) / width, (pixel_y + sampler.next_1d()) / height
        )
        wavelength_sample = sampler.next_1d()  # Mitsuba's argument; the wavelengths are drawn below
        aperture_sample = sampler.next_2d()
        ray, _ = self.sensor.sample_ray(0.0, wavelength_sample, film_position, aperture_sample)
        if self.lens is not None:  # a thin lens on the pinhole sensor (``thin_lens``)
            ray = self.lens.ray(mi, ray, aperture_sample)
        span = bands.wavelength_max_nm - bands.wavelength_min_nm
        # The hero set and each lane's weight (worker.render.wavelength_sampling): ρ_λ,j = (1/Λ)/p(λ_j).
        hero_set = self.wavelengths.sample(sampler.next_1d())
        wavelengths = hero_set.wavelengths
        lane_count = len(wavelengths)
        ray = mi.Ray3f(ray.o, ray.d, ray.maxt, ray.time, wavelengths)
        result = self.integrator.trace(self.scene, sampler, ray, mi.Bool(True), hero_set.ratios)

        radiance = [result.radiance[j] for j in range(lane_count)]
        if hero_set.ratios is not None:
            radiance = [radiance[j] * hero_set.ratios[j] for j in range(lane_count)]
        weights = lane_weights(span, lane_count, hero_set.ratios)
        band_scale = span / bands.width_nm / lane_count
        band_values = []
        for band in range(bands.band_count):
            value = mi.Float(0.0)
            for j in range(lane_count):
                value += dr.select(hero_set.band_of_lane[j] == band, radiance[j], 0.0)
            band_values.append(value * band_scale)
        luminance = mi.Float(0.0)
        for value, weight in zip(band_values, self._band_luminance, strict=True):
            luminance += value * weight
        albedo_xyz = [mi.Float(0.0), mi.Float(0.0), mi.Float(0.0)]
        cie = self.integrator.context.cie1931
        for j in range(lane_count):
            cmf = cie1931_xyz(mi, cie, wavelengths[j])
            for c in range(3):
                albedo_xyz[c] += cmf[c] * result.albedo[j] * weights[j] * mi.MI_CIE_Y_NORMALIZATION
        per_sample = {
            "diag_w": result.diag_weight,
            "diag_mxx": result.diag_mxx,
            "diag_mxy": result.diag_mxy,
            "diag_myy": result.diag_myy,
            "diag_r": result.diag_r,
            "diag_c2": result.diag_cos2,
            "diag_s2": result.diag_sin2,
            **vcz_sums(
                result.vcz_weight,
                result.vcz_r,
                result.vcz_direction,
                *self._environment_vcz(result),
            ),
            "depth": result.depth_m,
            "normal_x": result.normal.x,
            "normal_y": result.normal.y,
            "normal_z": result.normal.z,
            "albedo_x": albedo_xyz[0],
            "albedo_y": albedo_xyz[1],
            "albedo_z": albedo_xyz[2],
            "luminance": luminance,
            "luminance_sq": dr.square(luminance),
        }
        squares = [dr.square(value) for value in band_values]
        return band_values + squares + [per_sample[key] for key in SUM_KEYS]


@contextlib.contextmanager
def _collector_paused() -> Iterator[None]:
    """Python's cyclic garbage collector paused: a renderer is freed by it (renderers hold reference
    cycles), and freeing one's frozen pass while another pass records or replays aborts the process in
    drjit-core (seen in the test suite), so it must not run inside a frozen call."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


def vcz_sums(
    weight: Any,
    weighted_r: Any,
    direction: Any,
    direct_weight: Any = None,
    direct_direction: Any = None,
) -> dict[str, Any]:
    """Per-sample terms of the secondary-source estimator (``output.secondary_source_m``): the weight w, w²
    (for the effective sample count), w·r, and w·d, w·ddᵀ of the arrival direction d; with
    ``direct_weight``/``direct_direction`` (environment light by next-event estimation) a second weighted
    direction of the same sample, counted as its own VCZ sample (w² and the moments add)."""

    def sample_terms(w: Any, vector: Any) -> dict[str, Any]:
        d = (vector.x, vector.y, vector.z)
        terms = {"vcz_w": w, "vcz_w2": dr.square(w)}
        for i, axis in enumerate("xyz"):
            terms[f"vcz_d{axis}"] = w * d[i]
            for j in range(i, 3):
                terms[f"vcz_d{axis}{'xyz'[j]}"] = w * d[i] * d[j]
        return terms

    terms = sample_terms(weight, direction)
    if direct_weight is not None:
        direct = sample_terms(direct_weight, direct_direction)
        terms = {key: value + direct[key] for key, value in terms.items()}
    return {**terms, "vcz_r": weighted_r}


class RenderCanceledError(Exception):
    """A render stopped because ``should_stop`` returned True."""
