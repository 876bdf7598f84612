"""Russian roulette starts at ``rr_depth`` in ``max_depth``'s numbering (``integrator.roulette_applies``):
with rr_depth = 1 it may end a path at the camera-visible surface, as Mitsuba documents ``rr_depth`` and
its C++ ``path`` implements; prb.py's test (the index, not the depth) starts one vertex later."""

from __future__ import annotations

import numpy as np
import pytest

from worker.mitsuba_setup import configured_mitsuba
from worker.render.integrator import roulette_applies


@pytest.mark.parametrize("rr_depth", [1, 2, 5])
def test_roulette_applies_from_the_vertex_at_depth_rr_depth(rr_depth: int) -> None:
    mi = configured_mitsuba()
    vertex_index = np.arange(8)
    applies = np.asarray(roulette_applies(mi.UInt32(vertex_index), rr_depth))
    depth = vertex_index + 1  # the camera-visible surface is at depth 1 (max_depth = 1: emitters seen)
    np.testing.assert_array_equal(applies, depth >= rr_depth)
    assert applies[rr_depth - 1] and (rr_depth == 1 or not applies[rr_depth - 2])
