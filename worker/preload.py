"""Loading, in a queue worker's main process, what every forked work horse would otherwise load again for
each job: Mitsuba with the worker's variant and thread count, the renderer's modules and Mitsuba's
plugins, the image writers, data tables and caches (together ~1 s for a horse's first chunk, and still
~30 ms per job once the modules are imported).

No Dr.Jit backend is initialised here: its LLVM thread pool or CUDA context would not survive the fork.
"""

from __future__ import annotations

import atexit
import ctypes
import gc
import json
from pathlib import Path

import numpy as np

from hgcore.settings import Settings
from schemas import EXAMPLES_DIR, validate_scene
from schemas.scene import MAX_FILM_MODES
from worker.mitsuba_setup import configure_mitsuba


def preload_renderer(settings: Settings) -> None:
    """Configure Mitsuba from ``settings``, load the renderer and fill its caches; then tell the
    collector to leave the loaded objects alone."""
    _load_libraries(settings)
    _fill_caches(settings)
    # Objects that exist now are left alone by the collector, so a horse's garbage collections do not
    # copy the worker's memory pages (copy-on-write) that it would otherwise only read. Unfrozen at exit,
    # so that the interpreter's last collection still finalises them.
    gc.freeze()
    atexit.register(gc.unfreeze)


def _load_libraries(settings: Settings) -> None:
    mitsuba = configure_mitsuba(settings.variant, settings.render_threads)
    import OpenImageIO  # noqa: F401  (EXR writing, imported lazily by the merge step)
    import PIL.Image  # (preview PNG, idem)

    PIL.Image.init()  # registers the image plugins now, not at the first save in each horse (~20 ms)

    import worker.render.chunks
    import worker.tasks  # noqa: F401  (RQ imports each task by its dotted name, in every horse)
    from hgcore.artifacts.images import preview_png

    preview_png(np.zeros((1, 1, 3)))  # PIL's first PNG encoding (~2 ms); zlib starts no threads
    # Not so OpenImageIO: its first image output starts a thread pool that a forked horse would lack
    # (the horse's EXR writes then hang), so its ~2 ms first-use cost stays in each horse.

    # Mitsuba loads each plugin (a shared library: shapes, emitters, films, ...) on its first use in a
    # process. Loaded here, every horse finds them resident (~10 ms per job); loading starts no threads.
    for plugin in sorted((Path(mitsuba.__file__).parent / "plugins").glob("*.so")):
        ctypes.CDLL(str(plugin))


def _fill_caches(settings: Settings) -> None:
    from hgcore.optics import ior, spectra
    from hgcore.optics.sources import open_cylinder_coefficient_table, source_coefficients

    # The renderer's disk and rectangle source expansions (~3 ms each) and the open cylinder's mode tables
    # (one exact-integration pass over the obliquities, ~0.9 s, then ~5 ms per mode count).
    for modes in range(1, MAX_FILM_MODES + 1):
        source_coefficients("disk", modes)
        source_coefficients("rect", modes)
        open_cylinder_coefficient_table(modes)
    # Data tables: CIE colour matching functions, illuminants, metals' refractive indices.
    spectra.cie_cmf(550.0)
    for illuminant in spectra.ILLUMINANTS:
        spectra.cie_illuminant(illuminant, 550.0)
    for metal in ior.METALS:
        ior.metal_table(metal)
    # The first validation in a process fills pydantic's and abc's caches (~5 ms).
    for example in sorted(EXAMPLES_DIR.glob("*.json")):
        validate_scene(json.loads(example.read_text()), settings)
