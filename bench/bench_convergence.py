"""PLT (``hg_path``) against RLT (``rlt``): error vs samples per pixel and vs render time (issue 13, item 4).

For each scene of :data:`SCENES` (the Fig. 7 sphere-source shell and the Fig. 8 mirror scene, at
``RESOLUTION_PX``² and the example's own bands, modes and depth):

* a **reference**: ``hg_path`` at ``REFERENCE_SPP`` spp, rendered as two independent halves (distinct
  seeds). Its own error is estimated from the halves: with A, B the half images and R = (A + B)/2,
  R − truth has a quarter of the variance of A − B, so the reference's own ΔE₀₀ (a difference measure,
  linear in small differences) is ≈ ½·ΔE₀₀(A, B), and its relative RMSE per band is ½·rRMSE(A, B).
* the **levels** ``LEVELS`` = 16, 32, …, 4096 spp of each integrator from one sequence of 16-spp
  chunks (``LEVELS[0]``) with distinct seeds: level n is the sum of the chunks up to it, so every level's
  samples are a prefix of the 4096-spp run and the whole sequence costs one 4096-spp render. One chunk
  size because the renderer compiles a kernel per spp (≈ 0.8 s each at 64²); at 64² a 16-spp chunk
  costs what 1/16 of a 256-spp one does (0.11 s vs 2.3 s measured), so the chunking adds no overhead.
  The time of level n is the render time of its chunks (scene load plus ``Renderer.render_sums``, wall
  clock); one warm-up chunk per integrator compiles the kernels first and is reported separately
  (``compile_s``), so the times are those of a warm renderer.
* the **errors** of each level against the reference: ΔE₀₀ per pixel (``hgcore.image_metrics``: band
  radiances → XYZ → CIELAB at the exposure that maps the reference's 99th-percentile luminance to white,
  the regression runs' and the compare view's rule), its mean and 95th percentile; and per band
  rRMSE_b = √(mean_px (x_b − ref_b)²) / mean_px ref_b.
* ``reaches_p95_below_1``: the first level (spp and seconds) whose ΔE₀₀ p95 < 1. Monte Carlo noise
  falls as N^(−1/2), so where no level reaches it ``extrapolated_spp`` = N_last·p95_last² is given for
  an unbiased estimator, p95_last² less the reference's own p95² (``threshold_crossing``). RLT's error
  against the PLT reference also holds its *bias* (its mean differs where partial coherence matters),
  so there its p95 flattens out instead (``p95_ratio_last_two`` ≈ 1/√2 for pure noise, → 1 at a bias
  floor). ``extrapolated_seconds`` uses ``seconds_per_spp_median`` (the median time per spp over the
  levels' increments: robust to the shared machine's load spikes).

Results: stdout, ``bench/results/convergence.json`` (``convergence_quick.json`` for ``--quick``) and a
plot, ``docs/gallery/convergence.svg`` (ΔE₀₀ p95 vs spp and vs seconds, log–log; written by hand:
matplotlib is not in the project's environment). ``--quick``: 16², levels 16…64, a 256-spp reference,
for the test suite's smoke test (writes no plot). ``--resummarise``: recompute the summaries and the
plot of the stored ``convergence.json`` without rendering.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from bench.machine import RESULTS_DIR, cpu_model, cpu_reference_s, write_results
from hgcore.artifacts.images import images_from_sums
from hgcore.artifacts.layout import BandLayout
from hgcore.artifacts.pixel_sums import PixelSums
from hgcore.files import atomic_write_bytes
from hgcore.image_metrics import delta_e00_map, metric_exposure_ev
from schemas import EXAMPLES_DIR

SCENES = ("fig7_thin_film_sphere_light", "fig8_mirror_coherence")
INTEGRATORS = ("hg_path", "rlt")
RESOLUTION_PX = 64
LEVELS = tuple(16 * 2**i for i in range(9))  # 16 … 4096
REFERENCE_SPP = 32768
QUICK_RESOLUTION_PX = 16
QUICK_LEVELS = (16, 32, 64)
QUICK_REFERENCE_SPP = 256
#: Chunk size of the reference render (its progress is logged after each).
REFERENCE_CHUNK_SPP = 2048
DELTA_E_THRESHOLD = 1.0
REFERENCE_SEED = 0x5EED
LEVEL_SEEDS = {"hg_path": 0x1001, "rlt": 0x2002}
PLOT_PATH = Path(__file__).resolve().parents[1] / "docs" / "gallery" / "convergence.svg"


def bench_scene(name: str, resolution_px: int, integrator: str) -> dict[str, Any]:
    """The example ``name`` at resolution_px² with ``integrator``; its bands, modes and depth kept."""
    scene = json.loads((EXAMPLES_DIR / f"{name}.json").read_text())
    scene["film"] = {**scene["film"], "width": resolution_px, "height": resolution_px}
    scene["film"]["integrator"] = integrator
    return scene


def render_sums(scene: dict[str, Any], spp: int, seed: int) -> tuple[PixelSums, float]:
    """One chunk of ``spp`` samples per pixel with ``seed``: its sums and wall-clock seconds."""
    from schemas.validation import validate_scene
    from worker.render.chunks import renderer_for

    start = time.perf_counter()
    sums = renderer_for(validate_scene(scene)).render_sums(spp, seed)  # scene load included, as a chunk's
    return sums, time.perf_counter() - start


def chunk_seed(base: int, index: int) -> int:
    """The seed of chunk ``index`` of a sequence: ``plan_chunks``'s spacing, so that no two coincide."""
    from worker.render.chunks import plan_chunks

    return plan_chunks(index + 1, index + 1, base)[index].seed


def band_images(sums: PixelSums, bands: BandLayout) -> np.ndarray:
    """(H, W, B) mean band radiances of ``sums``."""
    return images_from_sums(sums, bands)["bands"].astype(np.float64)


def relative_rmse(sample: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Per band √(mean_px (x_b − ref_b)²) / mean_px ref_b (NaN for a band the reference leaves black)."""
    mean = reference.mean(axis=(0, 1))
    rmse = np.sqrt(np.mean((sample - reference) ** 2, axis=(0, 1)))
    return np.where(mean > 0, rmse / np.where(mean > 0, mean, 1.0), np.nan)


def errors(sample: np.ndarray, reference: np.ndarray, centers_nm: np.ndarray, ev: float) -> dict[str, Any]:
    """ΔE₀₀ mean and p95 over the pixels, and the per-band relative RMSE, of ``sample`` vs ``reference``."""
    delta_e = delta_e00_map(reference, sample, centers_nm, ev)
    rrmse = relative_rmse(sample, reference)
    return {
        "delta_e00_mean": float(np.mean(delta_e)),
        "delta_e00_p95": float(np.percentile(delta_e, 95)),
        "rel_rmse_per_band": [round(float(value), 6) for value in rrmse],
        "rel_rmse_mean": float(np.nanmean(rrmse)),
    }


def log(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def reference(name: str, resolution_px: int, spp: int) -> tuple[np.ndarray, dict[str, Any], BandLayout]:
    """The hg_path reference image of ``name`` and its self-error estimate from its two halves."""
    from schemas.validation import validate_scene

    scene = bench_scene(name, resolution_px, "hg_path")
    film = validate_scene(scene).film
    bands = BandLayout(film.wavelength_min_nm, film.wavelength_max_nm, film.bands)
    half_spp = spp // 2
    chunk_spp = min(REFERENCE_CHUNK_SPP, half_spp)
    halves: list[PixelSums] = []
    seconds = 0.0
    seed = 0
    for half in range(2):
        total: PixelSums | None = None
        done = 0
        while done < half_spp:
            count = min(chunk_spp, half_spp - done)
            sums, elapsed = render_sums(scene, count, chunk_seed(REFERENCE_SEED, seed))
            seed += 1
            seconds += elapsed
            total = sums if total is None else total.add(sums)
            done += count
            log(f"{name}: reference half {half + 1}/2, {done}/{half_spp} spp, {seconds:.0f} s")
        assert total is not None
        halves.append(total)
    image_a, image_b = band_images(halves[0], bands), band_images(halves[1], bands)
    image = band_images(halves[0].add(halves[1]), bands)
    ev = metric_exposure_ev(image, bands.centers_nm)
    between_halves = errors(image_a, image_b, bands.centers_nm, ev)
    self_error = {
        "spp": 2 * half_spp,
        "seconds": round(seconds, 2),
        "exposure_ev": ev,
        # R − truth has ¼ the variance of A − B: half its standard deviation.
        "delta_e00_mean": 0.5 * between_halves["delta_e00_mean"],
        "delta_e00_p95": 0.5 * between_halves["delta_e00_p95"],
        "rel_rmse_mean": 0.5 * between_halves["rel_rmse_mean"],
    }
    return image, self_error, bands


def seconds_per_spp(levels: list[dict[str, Any]]) -> float:
    """The median render time per spp over the levels' increments (level k−1 → k). The shared machine's
    load comes and goes (one increment was 4× slower than its neighbours in a run), so the median rate is
    the time a level needs on an unloaded machine of this kind; the levels' ``seconds`` are as measured."""
    rates = [
        (later["seconds"] - earlier["seconds"]) / (later["spp"] - earlier["spp"])
        for earlier, later in itertools.pairwise([{"spp": 0, "seconds": 0.0}, *levels])
    ]
    return float(np.median(rates))


def threshold_crossing(
    levels: list[dict[str, Any]], reference_p95: float, threshold: float
) -> dict[str, Any]:
    """The first level whose ΔE₀₀ p95 is below ``threshold``, else an N^(−1/2) extrapolation.

    The measured p95 holds the reference's own error too; the two are independent, so (to first order)
    p95² ≈ p95_level² + p95_reference², and the extrapolation uses p95_level² = p95² − p95_reference²:
    N_1 = N_last·p95_level²/threshold² (``extrapolated_spp``; ``extrapolated_spp_uncorrected`` without the
    correction), its time at ``seconds_per_spp`` (``extrapolated_seconds``)."""
    for level in levels:
        if level["delta_e00_p95"] < threshold:
            return {"spp": level["spp"], "seconds": level["seconds"], "extrapolated_spp": None}
    last = levels[-1]
    level_p95_sq = max(last["delta_e00_p95"] ** 2 - reference_p95**2, 0.0)
    extrapolated = last["spp"] * level_p95_sq / threshold**2
    return {
        "spp": None,
        "seconds": None,
        "extrapolated_spp": round(extrapolated),
        "extrapolated_spp_uncorrected": round(last["spp"] * (last["delta_e00_p95"] / threshold) ** 2),
        "extrapolated_seconds": round(extrapolated * seconds_per_spp(levels), 1),
    }


def summarise(results: dict[str, Any]) -> dict[str, Any]:
    """Add each run's ``reaches_p95_below_1``, ``seconds_per_spp_median`` and ``p95_ratio_last_two``."""
    threshold = results["threshold_delta_e00_p95"]
    for scene in results["scenes"].values():
        for integrator in INTEGRATORS:
            run = scene[integrator]
            levels = run["levels"]
            run["seconds_per_spp_median"] = seconds_per_spp(levels)
            run["reaches_p95_below_1"] = threshold_crossing(
                levels, scene["reference"]["delta_e00_p95"], threshold
            )
            before, last = levels[-2]["delta_e00_p95"], levels[-1]["delta_e00_p95"]
            run["p95_ratio_last_two"] = last / before if before > 0 else None
    return results


def convergence(
    name: str, integrator: str, levels: tuple[int, ...], resolution_px: int, ref: np.ndarray, ev: float
) -> dict[str, Any]:
    """Errors of ``integrator`` at each of ``levels`` (prefix sums of one chunk sequence) vs ``ref``."""
    scene = bench_scene(name, resolution_px, integrator)
    from schemas.validation import validate_scene

    film = validate_scene(scene).film
    bands = BandLayout(film.wavelength_min_nm, film.wavelength_max_nm, film.bands)
    start = time.perf_counter()
    chunk_spp = levels[0]
    if any(level % chunk_spp for level in levels):
        raise ValueError(f"levels: each must be a multiple of the first, {chunk_spp}")
    # Warm-up (its own seed, not one of the levels'): compiles the kernels.
    render_sums(scene, chunk_spp, chunk_seed(LEVEL_SEEDS[integrator], levels[-1]))
    compile_s = time.perf_counter() - start
    results = []
    total: PixelSums | None = None
    seconds = 0.0
    for index in range(levels[-1] // chunk_spp):
        sums, elapsed = render_sums(scene, chunk_spp, chunk_seed(LEVEL_SEEDS[integrator], index))
        seconds += elapsed
        total = sums if total is None else total.add(sums)
        if total.sample_count not in levels:
            continue
        level = {"spp": total.sample_count, "seconds": round(seconds, 3)}
        level.update(errors(band_images(total, bands), ref, bands.centers_nm, ev))
        results.append(level)
        log(
            f"{name} {integrator}: {level['spp']} spp {seconds:.1f} s ΔE00 p95 {level['delta_e00_p95']:.3f} "
            f"mean {level['delta_e00_mean']:.3f} rRMSE {level['rel_rmse_mean']:.4f}"
        )
    return {"compile_s": round(compile_s, 2), "levels": results}


def main(quick: bool = False, plot_path: Path | None = PLOT_PATH) -> dict[str, Any]:
    """Run the bench (small with ``quick``), write its JSON (and, unless quick, the plot) and return it."""
    from worker.mitsuba_setup import configure_mitsuba

    configure_mitsuba("llvm_ad_spectral")
    resolution = QUICK_RESOLUTION_PX if quick else RESOLUTION_PX
    levels = QUICK_LEVELS if quick else LEVELS
    reference_spp = QUICK_REFERENCE_SPP if quick else REFERENCE_SPP
    start = time.perf_counter()
    results: dict[str, Any] = {
        "machine": {"cpu": cpu_model(), "cpu_reference_s": cpu_reference_s()},
        "resolution_px": resolution,
        "levels_spp": list(levels),
        "threshold_delta_e00_p95": DELTA_E_THRESHOLD,
        "scenes": {},
    }
    for name in SCENES:
        ref, self_error, _ = reference(name, resolution, reference_spp)
        results["scenes"][name] = {
            "reference": self_error,
            **{
                integrator: convergence(name, integrator, levels, resolution, ref, self_error["exposure_ev"])
                for integrator in INTEGRATORS
            },
        }
    results["wall_s"] = round(time.perf_counter() - start, 1)
    return publish(
        summarise(results), "convergence_quick" if quick else "convergence", None if quick else plot_path
    )


def publish(results: dict[str, Any], name: str, plot_path: Path | None) -> dict[str, Any]:
    """Write ``bench/results/<name>.json`` (with its path in ``path``) and the plot (unless None)."""
    results["path"] = str(write_results(name, results))
    if plot_path is not None:
        atomic_write_bytes(plot_path, convergence_svg(results).encode())
    return results


def resummarise(plot_path: Path = PLOT_PATH) -> dict[str, Any]:
    """Recompute the summaries and the plot of the stored ``convergence.json`` without rendering."""
    results = json.loads((RESULTS_DIR / "convergence.json").read_text())
    return publish(summarise(results), "convergence", plot_path)


# --- the plot ------------------------------------------------------------------------------------------

COLOURS = {"hg_path": "#1f77b4", "rlt": "#d62728"}
DASHES = {SCENES[0]: "", SCENES[1]: "6,3"}


def log_ticks(log_low: float, log_high: float) -> list[float]:
    """Axis ticks 1, 2, 5 × 10^k between 10^log_low and 10^log_high."""
    ticks = [m * 10.0**e for e in range(math.floor(log_low), math.ceil(log_high) + 1) for m in (1, 2, 5)]
    return [t for t in ticks if log_low <= math.log10(t) <= log_high]


def convergence_svg(results: dict[str, Any]) -> str:
    """Two log–log panels, ΔE₀₀ p95 vs spp and vs render seconds, one line per scene and integrator,
    the p95 = 1 threshold dashed; the reference's own p95 as a dotted line per scene."""
    width, height, margin = 440, 300, 52
    panels = (("spp", "samples per pixel"), ("seconds", "render time (s)"))
    values = [
        level
        for scene in results["scenes"].values()
        for integrator in INTEGRATORS
        for level in scene[integrator]["levels"]
    ]
    y_values = [v["delta_e00_p95"] for v in values] + [DELTA_E_THRESHOLD]
    y_values += [scene["reference"]["delta_e00_p95"] for scene in results["scenes"].values()]
    y_low, y_high = math.log10(min(y_values) * 0.8), math.log10(max(y_values) * 1.25)
    parts = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{2 * width}" height="{height + 40}" '
        'font-family="sans-serif" font-size="11">',
        f'<rect width="{2 * width}" height="{height + 40}" fill="white"/>',
    ]
    for panel, (key, label) in enumerate(panels):
        x0 = panel * width
        xs = [v[key] for v in values if v[key] > 0]
        x_low, x_high = math.log10(min(xs) * 0.8), math.log10(max(xs) * 1.25)

        def px(x: float, x0: int = x0, x_low: float = x_low, x_high: float = x_high) -> float:
            return x0 + margin + (math.log10(x) - x_low) / (x_high - x_low) * (width - 1.5 * margin)

        def py(y: float) -> float:
            return 10 + (y_high - math.log10(y)) / (y_high - y_low) * (height - margin)

        left, right, top, bottom = x0 + margin, x0 + width - margin / 2, 10, 10 + height - margin
        parts.append(
            f'<rect x="{left}" y="{top}" width="{right - left}" height="{bottom - top}" '
            'fill="none" stroke="#444"/>'
        )
        for x in log_ticks(x_low, x_high):
            parts.append(
                f'<line x1="{px(x):.1f}" y1="{bottom}" x2="{px(x):.1f}" y2="{bottom + 4}" stroke="#444"/>'
            )
            parts.append(f'<text x="{px(x):.1f}" y="{bottom + 16}" text-anchor="middle">{x:g}</text>')
        for y in log_ticks(y_low, y_high):
            parts.append(
                f'<line x1="{left - 4}" y1="{py(y):.1f}" x2="{right}" y2="{py(y):.1f}" stroke="#ddd"/>'
            )
            parts.append(f'<text x="{left - 6}" y="{py(y) + 4:.1f}" text-anchor="end">{y:g}</text>')
        parts.append(f'<text x="{(left + right) / 2}" y="{bottom + 32}" text-anchor="middle">{label}</text>')
        parts.append(
            f'<text x="{x0 + 12}" y="{(top + bottom) / 2}" text-anchor="middle" '
            f'transform="rotate(-90 {x0 + 12} {(top + bottom) / 2})">ΔE₀₀ p95</text>'
        )
        parts.append(
            f'<line x1="{left}" y1="{py(DELTA_E_THRESHOLD):.1f}" x2="{right}" '
            f'y2="{py(DELTA_E_THRESHOLD):.1f}" stroke="#000" stroke-dasharray="2,2"/>'
        )
        for name, scene in results["scenes"].items():
            for integrator in INTEGRATORS:
                points = " ".join(
                    f"{px(v[key]):.1f},{py(v['delta_e00_p95']):.1f}" for v in scene[integrator]["levels"]
                )
                parts.append(
                    f'<polyline points="{points}" fill="none" stroke="{COLOURS[integrator]}" '
                    f'stroke-width="1.8" stroke-dasharray="{DASHES.get(name, "")}"/>'
                )
            ref_y = py(max(scene["reference"]["delta_e00_p95"], 10**y_low))
            parts.append(
                f'<line x1="{left}" y1="{ref_y:.1f}" x2="{right}" y2="{ref_y:.1f}" stroke="#888" '
                f'stroke-dasharray="1,3"/>'
            )
    legend_y = height + 22
    entries = [
        (f"{integrator} · {name}", COLOURS[integrator], DASHES.get(name, ""))
        for name in results["scenes"]
        for integrator in INTEGRATORS
    ]
    for index, (text, colour, dash) in enumerate(entries):
        x = 20 + index * (2 * width - 20) / len(entries)
        parts.append(
            f'<line x1="{x}" y1="{legend_y}" x2="{x + 24}" y2="{legend_y}" stroke="{colour}" '
            f'stroke-width="1.8" stroke-dasharray="{dash}"/>'
        )
        parts.append(f'<text x="{x + 28}" y="{legend_y + 4}">{text}</text>')
    parts.append("</svg>")
    return "\n".join(parts) + "\n"


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="16², 16…64 spp, 256-spp reference (smoke test)")
    parser.add_argument(
        "--resummarise",
        action="store_true",
        help="recompute convergence.json's summaries and plot, no render",
    )
    arguments = parser.parse_args()
    json.dump(resummarise() if arguments.resummarise else main(quick=arguments.quick), sys.stdout, indent=2)
    sys.stdout.write("\n")
