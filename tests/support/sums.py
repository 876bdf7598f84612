"""A renderer's per-pixel sums as plain arrays, and their bitwise comparison (frozen passes must replay
exactly what tracing computes)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from worker.render.renderer import Renderer

SUMS_SPP = 8
"""Samples per pixel of ``sums_of``'s pass: small, the comparisons are bitwise."""


def sums_of(renderer: Renderer, seed: int, spp: int = SUMS_SPP) -> dict[str, np.ndarray]:
    """Every per-pixel sum of one pass of ``renderer`` (bands, their squares and the diagnostics' sums)."""
    sums = renderer.render_sums(spp, seed)
    return {"bands": sums.bands, "bands_sq": sums.bands_sq, **sums.values}


def assert_bitwise_equal(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> None:
    assert a.keys() == b.keys()
    assert [key for key in a if not np.array_equal(a[key], b[key])] == []
