"""Street clutter helpers (dstenv.sim.clutter)."""

from __future__ import annotations

import numpy as np

from dstenv.sim.clutter import _bboxes


def test_building_boxes_in_one_reduction_equal_per_polygon_min_max():
    rng = np.random.default_rng(0)
    polys = [rng.uniform(-500, 500, (int(rng.integers(1, 12)), 2)) for _ in range(300)]
    ref = np.array([[*np.min(b, 0), *np.max(b, 0)] for b in polys])
    assert np.array_equal(_bboxes(polys), ref)
    assert _bboxes([]).shape == (0, 4)
    square = np.array([[1.0, 2.0], [4.0, 2.0], [4.0, 7.0], [1.0, 7.0]])
    assert np.array_equal(_bboxes([square]), [[1.0, 2.0, 4.0, 7.0]])
