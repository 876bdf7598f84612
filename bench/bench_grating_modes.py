"""Cost of the source's HG modes in gratings: ``fig1f_dvd_small_source`` at 16 modes against 1 (issue 26:
≤ 1.5×).

One mode is the Gaussian lobe; 16 are the disk's modal image blurred by the intrinsic lobe
(``hgcore.optics.grating.ModalLobe``): per wavelength the blurred coefficients, per order two Hermite
recurrences to degree 6 and 16 products. The scene is the example at ``SIZE_PX``², ``SPP`` spp, its 16 bands;
one ``Renderer`` per mode count, timed alternately for ``ROUNDS`` rounds (``bench.machine.paired_ratio``,
CPU seconds of ``render_sums``). The Cornell box (no grating, no film) is timed the same way as a control:
its ratio must be 1 (the modes cost nothing where nothing reads them). Results: stdout and
``bench/results/grating_modes.json``.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path
from typing import Any

from bench.machine import MachineLoad, paired_ratio, write_results
from schemas import EXAMPLES_DIR
from schemas.validation import validate_scene
from worker.mitsuba_setup import configure_mitsuba, configured_mitsuba

SIZE_PX, SPP = 96, 16
ROUNDS = 9
GOAL = 1.5


def _renders(name: str, modes: int, folder: Path) -> Any:
    """``render_sums`` of the example ``name`` at ``modes`` modes, as a function of the seed."""
    from hgcore.settings import SceneLimits
    from worker.render.renderer import Renderer
    from worker.render.scene_compiler import SceneCompiler

    scene = json.loads((EXAMPLES_DIR / f"{name}.json").read_text())
    scene["film"] = {**scene["film"], "width": SIZE_PX, "height": SIZE_PX, "spp": SPP, "modes": modes}
    limits = SceneLimits()  # this benchmark's process settings
    compiler = SceneCompiler(configured_mitsuba(), folder, limits=limits)
    compiled = compiler.compile(validate_scene(scene, limits))
    renderer = Renderer(compiled)
    return lambda seed: renderer.render_sums(SPP, seed)


def main() -> dict[str, Any]:
    configure_mitsuba("llvm_ad_spectral")  # this benchmark's entry point, before the renderer is imported
    load = MachineLoad()
    results: dict[str, Any] = {"size_px": SIZE_PX, "spp": SPP, "rounds": ROUNDS}
    with tempfile.TemporaryDirectory(prefix="hgrender-bench-grating-modes-") as tmp:
        folder = Path(tmp)
        for name, goal in (("fig1f_dvd_small_source", GOAL), ("cornell_box", 1.05)):
            pair = paired_ratio(_renders(name, 1, folder), _renders(name, 16, folder), ROUNDS, goal)
            print(name, json.dumps(pair))
            results[name] = pair
    results["machine"] = load.fields()
    write_results("grating_modes", results)
    return results


if __name__ == "__main__":
    main()
