"""Environment sampling: variance of a diffuse sphere under an HDR map, ``hg_path`` against Mitsuba's
``path`` with the same ``envmap`` at equal spp (issue 27: no worse).

Scene: a grey diffuse sphere (ρ 0.5) filling half of a 48² image under a 256 × 128 lat-long sky (a
gradient, a ground and a sun-like patch of 8 × 4 texels 400× brighter than the sky: the case importance
sampling is for), one band over 380–780 nm (so spectral sampling adds the same noise to both: four
wavelengths per path, uniform in the band), max depth 4.

Both integrators render ``SEEDS`` independent images at ``SPP`` spp (Mitsuba's through a one-band
``specfilm``, tests/support/reference.py); per pixel the variance across the seeds estimates the variance of
a ``SPP``-sample estimate. Reported: the mean of the per-pixel variances over the sphere's pixels and over
the image, each integrator's image mean (they must agree), and the ratio hg_path/path with the relative
standard error of each mean variance (from the spread of the per-pixel variances). Results: stdout and
``bench/results/environment.json``.
"""

from __future__ import annotations

import json
import math
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from bench.machine import MachineLoad, write_results
from schemas.validation import validate_scene
from worker.mitsuba_setup import configure_mitsuba, configured_mitsuba

SIZE_PX, SPP = 48, 16
SEEDS = 24
RADIUS_M, DISTANCE_M, FOV_DEG = 0.5, 2.2, 30.0


def scene() -> dict[str, Any]:
    return {
        "schema": "hgrender/scene/v1",
        "name": "diffuse sphere under an HDR sky",
        "camera": {"origin_m": [0, 0, DISTANCE_M], "target_m": [0, 0, 0], "fov_deg": FOV_DEG},
        "film": {"width": SIZE_PX, "height": SIZE_PX, "spp": SPP, "bands": 1, "max_depth": 4},
        "materials": {"grey": {"type": "diffuse", "reflectance": 0.5}},
        "shapes": [{"type": "sphere", "material": "grey", "center_m": [0, 0, 0], "radius_m": RADIUS_M}],
        "emitters": [{"type": "environment", "path": "sky.exr"}],
    }


def on_sphere() -> np.ndarray:
    half = math.tan(math.radians(FOV_DEG) / 2.0)
    centres = ((np.arange(SIZE_PX) + 0.5) / SIZE_PX * 2.0 - 1.0) * half
    x, y = np.meshgrid(centres, centres)
    return np.arctan(np.hypot(x, y)) < math.asin(RADIUS_M / DISTANCE_M) - 2.0 * half / SIZE_PX


def _summary(renders: np.ndarray, mask: np.ndarray) -> dict[str, float]:
    variance = renders.var(axis=0, ddof=1)
    result = {}
    for name, region in (("sphere", mask), ("image", np.ones_like(mask))):
        values = variance[region]
        result[f"{name}_mean_variance"] = float(values.mean())
        result[f"{name}_variance_rel_se"] = float(values.std(ddof=1) / math.sqrt(values.size) / values.mean())
        result[f"{name}_mean"] = float(renders.mean(axis=0)[region].mean())
    return result


def main() -> dict[str, Any]:
    configure_mitsuba("llvm_ad_spectral")  # this benchmark's entry point, before the renderer is imported
    import OpenImageIO as oiio

    from hgcore.settings import SceneLimits
    from tests.support.images import sky_image
    from tests.support.reference import band_box_specfilm
    from worker.render.renderer import Renderer
    from worker.render.scene_compiler import SceneCompiler

    load = MachineLoad()
    mi = configured_mitsuba()
    with tempfile.TemporaryDirectory(prefix="hgrender-bench-environment-") as tmp:
        folder = Path(tmp)
        image = sky_image(256, 128, (slice(40, 44), slice(80, 88)), (400.0, 360.0, 300.0))
        output = oiio.ImageOutput.create(str(folder / "sky.exr"))
        output.open(str(folder / "sky.exr"), oiio.ImageSpec(image.shape[1], image.shape[0], 3, "float"))
        output.write_image(image)
        output.close()
        compiled = SceneCompiler(mi, folder, limits=SceneLimits()).compile(validate_scene(scene()))
        renderer = Renderer(compiled)
        ours = []
        for seed in range(SEEDS):
            sums = renderer.render_sums(SPP, seed + 1)
            ours.append((sums.bands / SPP).reshape(SIZE_PX, SIZE_PX))
        reference_dict = dict(compiled.reference_dict)
        reference_dict["sensor"] = {**reference_dict["sensor"], "film": band_box_specfilm(compiled)}
        reference_dict["integrator"] = {"type": "path", "max_depth": 4}
        reference_scene = mi.load_dict(reference_dict, optimize=False)
        theirs = [
            np.array(mi.render(reference_scene, spp=SPP, seed=seed + 1), dtype=np.float64)[..., 0]
            for seed in range(SEEDS)
        ]
    mask = on_sphere()
    hg, path = _summary(np.stack(ours), mask), _summary(np.stack(theirs), mask)
    results = {
        "size_px": SIZE_PX,
        "spp": SPP,
        "seeds": SEEDS,
        "hg_path": hg,
        "mitsuba_path": path,
        "variance_ratio_sphere": hg["sphere_mean_variance"] / path["sphere_mean_variance"],
        "variance_ratio_image": hg["image_mean_variance"] / path["image_mean_variance"],
        "note": "ratio ≤ 1 within the relative standard errors means no worse than Mitsuba's envmap sampling",
        "machine": load.fields(),
    }
    print(json.dumps(results, indent=1))
    write_results("environment", results)
    return results


if __name__ == "__main__":
    main()
