"""Noise-target rendering: add passes until a render's relative standard error meets a target, or a wall
time budget runs out, instead of rendering a fixed spp.

Two error measures, from the per-pixel sums (Σx and Σx² over N samples per pixel, ``PixelSums``):

* band means (default): for band b the image mean m_b = (1/P) Σ_p x̄_pb has the variance
  Var(m_b) = (1/P²) Σ_p s²_pb / N with s²_pb = Σx²/N − x̄² (pixels are independent), so its relative
  standard error is e_b = √Var(m_b) / m_b; the render's error is max_b e_b over bands with light (m_b > 0).
* luminance per pixel at a quantile q (``quantile``): e_p = √(s²_p / N) / Ȳ_p for the pixel luminance Y
  (CIE Y, the ``luminance`` sums), over pixels with Ȳ_p > 0; the render's error is the q-quantile of e_p
  (q = 0.5: the median pixel meets the target; q = 0.9: nine pixels in ten).

Both fall as 1/√N, so after a round of N samples with error e the total that just meets E is predicted
as N·(e/E)²; the next round renders the difference (at least N/16 so that rounds stay worth their
overhead, at most 8N so that a lucky low early estimate cannot run away), capped by the time left at the
rate measured so far. Each round is a chunk with the next chunk index's seed (the renderer's
``worker.render.chunks.chunk_seed``), so
the result is the same as a fixed render of those chunks: bitwise deterministic given the target (a time
budget makes the number of rounds depend on the machine's speed, by nature).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from hgcore.artifacts.pixel_sums import PixelSums, variance_of_mean
from hgcore.errors import InputError

MIN_ROUND_FRACTION = 1 / 16
MAX_ROUND_GROWTH = 8


@dataclass(frozen=True)
class NoiseTarget:
    """What a noise-target render stops at: ``rel_error`` (relative standard error, e.g. 0.01 = 1 %),
    ``time_budget_s`` (wall seconds for the rendering), or both (whichever comes first); ``quantile``
    selects the per-pixel luminance measure (None: band means)."""

    rel_error: float | None = None
    time_budget_s: float | None = None
    quantile: float | None = None

    def __post_init__(self) -> None:
        if self.quantile is not None:
            if self.rel_error is None:
                raise InputError("target_quantile: needs target_rel_error")
            if not 0 < self.quantile <= 1:
                raise InputError(f"target_quantile: must be in (0, 1], got {self.quantile}")
        if self.rel_error is None and self.time_budget_s is None:
            raise InputError("target_rel_error: a noise target needs target_rel_error or time_budget_s")
        if self.rel_error is not None and not (0 < self.rel_error < 1 and math.isfinite(self.rel_error)):
            raise InputError(f"target_rel_error: must be in (0, 1), got {self.rel_error}")
        if self.time_budget_s is not None and not (
            self.time_budget_s > 0 and math.isfinite(self.time_budget_s)
        ):
            raise InputError(f"time_budget_s: must be positive, got {self.time_budget_s}")

    @classmethod
    def from_options(
        cls, rel_error: float | None, time_budget_s: float | None, quantile: float | None
    ) -> NoiseTarget | None:
        """The target of a request's options, or None when it asks for none (a fixed-spp render)."""
        if rel_error is None and time_budget_s is None and quantile is None:
            return None
        return cls(rel_error, time_budget_s, quantile)

    @property
    def metric(self) -> str:
        return "band_mean" if self.quantile is None else "luminance_quantile"


class ImageErrors:
    """The two error measures (module docstring) accumulated over an image's row bands, so that a render
    never needs its whole image's sums at once: per band Σ_p x̄_pb and Σ_p s²_pb/N over the pixels, and
    the luminance relative error e_p of every lit pixel (8 bytes a pixel)."""

    def __init__(self) -> None:
        self.sample_count = 0
        self.pixels = 0
        self.band_mean_sum: np.ndarray | None = None
        self.band_variance_sum: np.ndarray | None = None
        self._luminance_errors: list[np.ndarray] = []

    @classmethod
    def of(cls, sums: Iterable[PixelSums]) -> ImageErrors:
        """The errors of an image given as row bands (or one whole-image ``PixelSums`` in a list)."""
        errors = cls()
        for part in sums:
            errors.add(part)
        return errors

    def add(self, sums: PixelSums) -> None:
        """Count one row band's pixels (every band has the same ``sample_count``)."""
        count = float(sums.sample_count)
        self.sample_count = sums.sample_count
        # Band by band: the temporaries are one band of the rows, not all of them (a tile of 32 bands
        # would need ~0.25 GB of them at once).
        band_count = sums.bands.shape[-1]
        band_mean, band_variance = np.zeros(band_count), np.zeros(band_count)
        for band in range(band_count):
            mean = sums.bands[..., band] / count
            band_mean[band] = mean.sum()
            band_variance[band] = variance_of_mean(
                sums.bands[..., band], sums.bands_sq[..., band], sums.sample_count
            ).sum()
        if self.band_mean_sum is None or self.band_variance_sum is None:
            self.band_mean_sum, self.band_variance_sum = band_mean, band_variance
        else:
            self.band_mean_sum, self.band_variance_sum = (
                self.band_mean_sum + band_mean,
                self.band_variance_sum + band_variance,
            )
        self.pixels += sums.bands.shape[0] * sums.bands.shape[1]
        luminance = sums.values["luminance"] / count
        luminance_variance = variance_of_mean(
            sums.values["luminance"], sums.values["luminance_sq"], sums.sample_count
        )
        lit = luminance > 0
        self._luminance_errors.append(np.sqrt(luminance_variance[lit]) / luminance[lit])

    def band_rel_errors(self) -> np.ndarray:
        """e_b, the relative standard error of each band's image mean (0 for a band without light)."""
        assert self.band_mean_sum is not None and self.band_variance_sum is not None
        image_mean = self.band_mean_sum / self.pixels
        image_std = np.sqrt(self.band_variance_sum) / self.pixels
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(image_mean > 0, image_std / image_mean, 0.0)

    def luminance_rel_error(self, quantile: float) -> float:
        """The ``quantile`` of the per-pixel luminance relative error over lit pixels (0 if none)."""
        errors = np.concatenate(self._luminance_errors) if self._luminance_errors else np.zeros(0)
        return float(np.quantile(errors, quantile)) if errors.size else 0.0

    def achieved(self, target: NoiseTarget) -> float:
        """The render's error in ``target``'s measure."""
        if target.quantile is not None:
            return self.luminance_rel_error(target.quantile)
        return float(self.band_rel_errors().max(initial=0.0))


def next_round_spp(
    target: NoiseTarget, spp_done: int, error: float, seconds_done: float, elapsed_s: float, max_spp: int
) -> int:
    """Samples per pixel of the next round (0: stop). ``seconds_done``: render time of the ``spp_done``
    samples so far; ``elapsed_s``: wall time since the render started (the budget's clock); ``max_spp``:
    the most samples per pixel a render may have in all."""
    if target.rel_error is not None:
        if error <= target.rel_error:
            return 0
        wanted = math.ceil(spp_done * (error / target.rel_error) ** 2) - spp_done
        wanted = min(max(wanted, math.ceil(spp_done * MIN_ROUND_FRACTION), 1), MAX_ROUND_GROWTH * spp_done)
    else:
        wanted = MAX_ROUND_GROWTH * spp_done
    if target.time_budget_s is not None:
        remaining_s = target.time_budget_s - elapsed_s
        seconds_per_spp = seconds_done / spp_done if spp_done else 0.0
        if seconds_per_spp > 0:
            wanted = min(wanted, int(remaining_s / seconds_per_spp))
        elif remaining_s <= 0:
            wanted = 0
    return max(0, min(wanted, max_spp - spp_done))


def stop_reason(target: NoiseTarget, error: float, spp_done: int, max_spp: int) -> str:
    """Why the rounds ended: ``target_met``, ``max_spp`` or ``time_budget``."""
    if target.rel_error is not None and error <= target.rel_error:
        return "target_met"
    return "max_spp" if spp_done >= max_spp else "time_budget"


def summary_block(
    target: NoiseTarget, errors: ImageErrors, rounds: list[dict[str, Any]], reason: str | None
) -> dict[str, Any]:
    """The ``noise_target`` block of ``summary.json``: the request, the achieved error in its measure and
    per band, whether it was met, why the rounds stopped and each round's spp, seconds and error. While
    a job still renders, the same block of the rounds so far (``reason`` None) is its view's progress."""
    band_errors = errors.band_rel_errors()  # once: the band-mean measure is its maximum
    if target.quantile is not None:
        error = errors.luminance_rel_error(target.quantile)
    else:
        error = float(band_errors.max(initial=0.0))
    return {
        "target_rel_error": target.rel_error,
        "time_budget_s": target.time_budget_s,
        "target_quantile": target.quantile,
        "metric": target.metric,
        "achieved_rel_error": error,
        "band_rel_error": band_errors.tolist(),
        "met": target.rel_error is not None and error <= target.rel_error,
        "stop_reason": reason,
        "spp": errors.sample_count,
        "rounds": rounds,
    }
