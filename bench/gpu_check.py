"""GPU readiness check (issue 16, item 6): on a machine with an NVIDIA GPU, render the Cornell box and a
thin-film example in ``cuda_ad_spectral`` and in ``llvm_ad_spectral`` (same scene, spp and seed), check
that the GPU image agrees with the CPU one within Monte Carlo error, and record samples/s of both.

Agreement, per scene and band: the image means m_gpu, m_cpu (over all pixels) differ by less than
``Z_LIMIT``·σ with σ² = σ²_gpu + σ²_cpu, σ² = Σ_p Var(x̄_p)/P² from each render's ``variance.exr`` (pixels
independent). The two backends draw the same PCG32 streams, so their samples differ only by floating-point
arithmetic and the bound is conservative; a wrong GPU result (a missing term, a different sampling) is
many σ off. Each render runs ``hgrender render`` in a subprocess with ``--variant``; the whole check is
bounded by ``bench/gpu_check.sh``'s timeout (5 min).

Without a GPU (no ``nvidia-smi``, or it lists none, or Mitsuba has no ``cuda_ad_spectral``) it prints
``{"gpu": null, "skipped": "<why>"}`` and exits 0 without rendering or writing results; with one it writes
``bench/results/gpu_check.json`` and exits 1 if a scene disagrees.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from bench.machine import cpu_model, write_results
from schemas import EXAMPLES_DIR

SCENES = ("cornell_box", "thin_film_sphere_light")
RESOLUTION_PX = 128
SPP = 64
BANDS = 16
SEED = 7
Z_LIMIT = 5.0
ROOT = Path(__file__).resolve().parent.parent


def gpu_name() -> tuple[str | None, str]:
    """(the first NVIDIA GPU's name, '') or (None, why there is none)."""
    smi = shutil.which("nvidia-smi")
    if smi is None:
        return None, "nvidia-smi not found"
    listed = subprocess.run([smi, "-L"], capture_output=True, text=True, check=False, timeout=30)
    gpus = [line for line in listed.stdout.splitlines() if line.startswith("GPU ")]
    if listed.returncode != 0 or not gpus:
        return None, "nvidia-smi lists no GPU"
    return gpus[0].split(":", 1)[1].split("(UUID")[0].strip(), ""


def cuda_variant_available() -> tuple[bool, str]:
    command = [sys.executable, "-c", "import mitsuba as mi; mi.set_variant('cuda_ad_spectral')"]
    done = subprocess.run(command, capture_output=True, text=True, check=False, timeout=120)
    return done.returncode == 0, (done.stderr.strip().splitlines() or [""])[-1]


def render(scene_path: Path, out_dir: Path, variant: str) -> dict[str, Any]:
    """``hgrender render`` in a subprocess; its JSON line plus the wall time (s)."""
    cli = "import sys; from hgrender.cli import main; sys.exit(main())"
    command = [sys.executable, "-c", cli, "render", str(scene_path), "-o", str(out_dir)]
    command += ["--variant", variant, "--quiet"]
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True, check=True, cwd=ROOT)
    return {**json.loads(done.stdout.strip().splitlines()[-1]), "wall_s": time.perf_counter() - start}


def band_means(out_dir: Path) -> tuple[list[float], list[float]]:
    """Per band: the image mean and its standard error (from variance.exr)."""
    from hgcore.artifacts.exr import read_exr

    image, variance = read_exr(out_dir / "image.exr"), read_exr(out_dir / "variance.exr")
    means, errors = [], []
    for name in image.band_names():
        pixels = image.channels[name].size
        means.append(float(image.channels[name].astype("float64").mean()))
        errors.append(math.sqrt(float(variance.channels[name].astype("float64").sum())) / pixels)
    return means, errors


def check_scene(name: str, work: Path) -> dict[str, Any]:
    scene = json.loads((EXAMPLES_DIR / f"{name}.json").read_text())
    film = {"width": RESOLUTION_PX, "height": RESOLUTION_PX, "spp": SPP, "bands": BANDS, "seed": SEED}
    scene["film"] = {**scene["film"], **film}
    scene_path = work / f"{name}.json"
    scene_path.write_text(json.dumps(scene))
    result: dict[str, Any] = {"scene": name}
    means = {}
    for variant in ("llvm_ad_spectral", "cuda_ad_spectral"):
        out = render(scene_path, work / f"{name}-{variant}", variant)
        result[variant] = {"samples_per_second": out["samples_per_second"], "wall_s": out["wall_s"]}
        means[variant] = band_means(work / f"{name}-{variant}")
    (cpu, cpu_err), (gpu, gpu_err) = means["llvm_ad_spectral"], means["cuda_ad_spectral"]
    z = [
        abs(g - c) / math.hypot(ge, ce) if ge or ce else 0.0
        for g, c, ge, ce in zip(gpu, cpu, gpu_err, cpu_err, strict=True)
    ]
    result |= {"band_z": z, "max_z": max(z), "agrees": max(z) < Z_LIMIT}
    return result


def main() -> int:
    name, why = gpu_name()
    if name is None:
        print(json.dumps({"gpu": None, "skipped": why}))
        return 0
    available, why = cuda_variant_available()
    if not available:
        print(json.dumps({"gpu": name, "skipped": f"Mitsuba has no cuda_ad_spectral: {why}"}))
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        scenes = [check_scene(scene, Path(tmp)) for scene in SCENES]
    results = {
        "gpu": name,
        "cpu_model": cpu_model(),
        "cpu_count": os.cpu_count(),
        "resolution_px": RESOLUTION_PX,
        "spp": SPP,
        "bands": BANDS,
        "z_limit": Z_LIMIT,
        "scenes": scenes,
        "agrees": all(s["agrees"] for s in scenes),
    }
    write_results("gpu_check", results)
    print(json.dumps(results, indent=2))
    return 0 if results["agrees"] else 1


if __name__ == "__main__":
    sys.exit(main())
