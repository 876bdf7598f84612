"""Cost of textures: a textured scene against the same scene with constant parameters (issue 27: ≤ 1.15×).

Pairs, each rendered by one ``Renderer`` per variant in this process (kernels compiled in a warm-up render
each), 64 × 64 px, 64 spp, 16 bands:

* ``cornell_one_wall``: the Cornell box example, and the same with its back wall's reflectance a 512² sRGB
  texture of smooth stripes and a grid (a typical textured asset: one textured material among others);
* ``cornell_every_surface``: the worst case: every diffuse material's reflectance a 256² sRGB texture of
  per-texel noise (±30 %), so every vertex does a colour lookup (four texels' coefficients, a spectrum each
  at four wavelengths) in 4 MiB of texels that no cache holds;
* ``thin_film``: the thin-film example under a sphere light, and the same with the film's thickness a 256²
  float texture (± 20 % around its thickness, bilinear): a scalar lookup feeding the film's shear and phase.

Both Cornell variants give the boxes (inline meshes) planar texture coordinates in the constant scene too,
so the pairs differ by the textures alone. Mitsuba's own ``path`` with its ``bitmap`` textures is timed on the
same worst-case pair for reference (``mitsuba_path_every_surface``).

Timing: CPU seconds (``time.process_time``, both threads: robust to the other users of the machine) of
``render_sums``, the two variants alternated for ``ROUNDS`` rounds, the order reversed every round;
``paired_ratio`` is the median over rounds of textured/constant of the adjacent pair, with wall-clock
ratios beside it. Results: stdout and ``bench/results/textures.json``.
"""

from __future__ import annotations

import copy
import json
import statistics
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from bench.machine import MachineLoad, paired_ratio, write_results
from schemas import EXAMPLES_DIR
from schemas.validation import validate_scene
from worker.mitsuba_setup import configure_mitsuba, configured_mitsuba

if TYPE_CHECKING:
    from worker.render.renderer import Renderer

SIZE_PX, SPP, BANDS = 96, 64, 16
ROUNDS = 15
TEXELS = 256
GOAL = 1.15


def _example(name: str) -> dict[str, Any]:
    scene = json.loads((EXAMPLES_DIR / f"{name}.json").read_text())
    scene["film"] = {**scene["film"], "width": SIZE_PX, "height": SIZE_PX, "bands": BANDS, "spp": SPP}
    return scene


def _write_image(path: Path, pixels: np.ndarray) -> None:
    import OpenImageIO as oiio

    output = oiio.ImageOutput.create(str(path))
    pixel_format = "uint8" if pixels.dtype == np.uint8 else "float"
    output.open(str(path), oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], pixel_format))
    output.write_image(np.ascontiguousarray(pixels))
    output.close()


def _encoded(linear: np.ndarray) -> np.ndarray:
    linear = np.clip(linear, 0.0, 1.0)
    encoded = np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)
    return np.round(encoded * 255).astype(np.uint8)


def _with_uvs(scene: dict[str, Any]) -> dict[str, Any]:
    """The scene with planar texture coordinates on its inline meshes (the Cornell box's boxes)."""
    scene = copy.deepcopy(scene)
    for shape in scene["shapes"]:
        if shape["type"] == "mesh":
            vertices = np.asarray(shape["vertices_m"])
            shape["uvs"] = (vertices[:, [0, 2]] + vertices[:, [1, 1]]).tolist()
    return scene


def _every_surface(scene: dict[str, Any], folder: Path) -> dict[str, Any]:
    textured = copy.deepcopy(scene)
    rng = np.random.default_rng(1)
    for name, material in textured["materials"].items():
        if material["type"] != "diffuse" or not isinstance(material["reflectance"], float):
            continue
        noise = rng.uniform(0.7, 1.3, size=(TEXELS, TEXELS, 1))
        _write_image(folder / f"{name}.png", _encoded(material["reflectance"] * noise * [1.0, 0.9, 0.8]))
        material["reflectance"] = {"type": "image", "path": f"{name}.png"}
    return textured


def _one_wall(scene: dict[str, Any], folder: Path) -> dict[str, Any]:
    textured = copy.deepcopy(scene)
    wall = next(s for s in textured["shapes"] if s["type"] == "rectangle" and s["normal"][2] > 0.5)
    size = 2 * TEXELS
    x = (np.arange(size) + 0.5) / size
    stripes = 0.45 + 0.3 * np.sin(2 * np.pi * 6 * x)[None, :, None] * np.array([1.0, 0.7, 0.3])
    grid = (np.minimum(x[:, None] * 16 % 1.0, x[None, :] * 16 % 1.0) < 0.06)[..., None]
    image = np.where(grid, 0.1, np.broadcast_to(stripes, (size, size, 3)))
    _write_image(folder / "wall.png", _encoded(image))
    textured["materials"]["textured_wall"] = {
        "type": "diffuse",
        "reflectance": {"type": "image", "path": "wall.png"},
    }
    wall["material"] = "textured_wall"
    return textured


def _textured_film(scene: dict[str, Any], folder: Path) -> dict[str, Any]:
    textured = copy.deepcopy(scene)
    for material in textured["materials"].values():
        if material["type"] == "thin_film":
            thickness = material["film_thickness_um"]
            values = np.random.default_rng(2).uniform(0.8, 1.2, (TEXELS, TEXELS, 1)) * thickness
            _write_image(folder / "thickness.exr", values.astype(np.float32))
            material["film_thickness_um"] = {"type": "image", "path": "thickness.exr"}
    return textured


def _renderer(scene: dict[str, Any], folder: Path) -> Renderer:
    from hgcore.settings import SceneLimits
    from worker.render.renderer import Renderer
    from worker.render.scene_compiler import SceneCompiler

    return Renderer(
        SceneCompiler(configured_mitsuba(), folder, limits=SceneLimits()).compile(validate_scene(scene))
    )


def _pair(constant: Renderer, textured: Renderer) -> dict[str, Any]:
    """textured/constant over ``ROUNDS`` alternated rounds (``bench.machine.paired_ratio``)."""
    pair = paired_ratio(
        lambda seed: constant.render_sums(SPP, seed),  # host sums: the kernels have run
        lambda seed: textured.render_sums(SPP, seed),
        ROUNDS,
        GOAL,
    )
    renamed = {"baseline_cpu_s": "constant_cpu_s", "candidate_cpu_s": "textured_cpu_s"}
    return {renamed.get(key, key): value for key, value in pair.items()}


def _mitsuba_pair(constant: dict[str, Any], textured: dict[str, Any], folder: Path) -> dict[str, Any]:
    """The same pair rendered by Mitsuba's ``path`` (its BSDFs: ``diffuse`` with ``bitmap`` textures)."""
    from hgcore.settings import SceneLimits
    from worker.render.scene_compiler import SceneCompiler

    mi = configured_mitsuba()

    def loaded(scene: dict[str, Any]) -> Any:
        compiled = SceneCompiler(mi, folder, limits=SceneLimits()).compile(validate_scene(scene))
        reference = {**compiled.reference_dict, "integrator": {"type": "path", "max_depth": 8}}
        return mi.load_dict(reference, optimize=False)

    scenes = {"constant": loaded(constant), "textured": loaded(textured)}
    ratios = []
    for name in scenes:
        np.array(mi.render(scenes[name], spp=SPP, seed=0))
    for round_index in range(ROUNDS):
        order = list(scenes) if round_index % 2 == 0 else list(scenes)[::-1]
        measured = {}
        for name in order:
            start = time.process_time()
            np.array(mi.render(scenes[name], spp=SPP, seed=round_index + 1))
            measured[name] = time.process_time() - start
        ratios.append(measured["textured"] / measured["constant"])
    return {"paired_ratio_cpu": statistics.median(ratios), "ratios_cpu": ratios}


def main() -> dict[str, Any]:
    configure_mitsuba("llvm_ad_spectral")  # this benchmark's entry point, before the renderer is imported
    load = MachineLoad()
    results: dict[str, Any] = {"size_px": SIZE_PX, "spp": SPP, "bands": BANDS, "rounds": ROUNDS}
    with tempfile.TemporaryDirectory(prefix="hgrender-bench-textures-") as tmp:
        folder = Path(tmp)
        cornell = _with_uvs(_example("cornell_box"))
        for name, scene, textured in (
            ("cornell_one_wall", cornell, _one_wall),
            ("cornell_every_surface", cornell, _every_surface),
            ("thin_film", _example("thin_film_sphere_light"), _textured_film),
        ):
            pair = _pair(_renderer(scene, folder), _renderer(textured(scene, folder), folder))
            print(name, json.dumps(pair))
            results[name] = pair
        results["mitsuba_path_every_surface"] = _mitsuba_pair(
            cornell, _every_surface(cornell, folder), folder
        )
        print("mitsuba_path_every_surface", json.dumps(results["mitsuba_path_every_surface"]))
    results["machine"] = load.fields()
    write_results("textures", results)
    return results


if __name__ == "__main__":
    main()
