"""Beam paths: traced cells, the rounding margin, shared prefixes, when tables are made."""

from __future__ import annotations

import numpy as np

from dstenv.grid import GridSpec
from dstenv.sensing.beampaths import NO_PATHS, BeamPaths, paths_for

SPEC = GridSpec(16, 16, 1.0)  # ego cell (8, 8); cell (i, j) centre x = 8 - i, y = 8 - j


def _cells(p: BeamPaths, k: int) -> list[tuple[int, int]]:
    flat = p.cells[p.start[k]:p.start[k + 1]].astype(int)
    return [(int(q) // SPEC.width, int(q) % SPEC.width) for q in flat]


def test_axis_beams_run_straight_to_the_border():
    # forward (+x: rows up), left (+y: columns left), backward, right
    p = BeamPaths(np.array([0.0, np.pi / 2, np.pi, -np.pi / 2]), SPEC, 80.0, 0.0, 0.0)
    assert _cells(p, 0) == [(i, 8) for i in range(8, -1, -1)]
    assert _cells(p, 1) == [(8, j) for j in range(8, -1, -1)]
    assert _cells(p, 2) == [(i, 8) for i in range(8, 16)]
    assert _cells(p, 3) == [(8, j) for j in range(8, 16)]
    # row steps among the first m steps, up to the step that leaves the grid
    np.testing.assert_array_equal(p.isteps[0:10], np.arange(10))
    np.testing.assert_array_equal(p.isteps[p.start[1] + 1:p.start[2] + 2], np.zeros(10))


def test_a_generic_beam_follows_its_crossings():
    # 30 deg from the centre of the ego cell: u = 8.5 - t cos, v = 8.5 - t sin. Rows
    # are crossed at t = 0.577, 1.732, ...; columns at t = 1, 3, ...
    p = BeamPaths(np.array([np.pi / 6]), SPEC, 80.0, 0.0, 0.0)
    assert _cells(p, 0)[:6] == [(8, 8), (7, 8), (7, 7), (6, 7), (5, 7), (5, 6)]
    assert p.safe[0]


def test_corner_beams_are_not_trusted_but_others_are():
    # 45 deg from a cell centre passes exactly through cell corners: a tie that
    # rounding decides differently for different ranges
    p = BeamPaths(np.array([np.pi / 4, 0.3, -2.0]), SPEC, 80.0, 0.0, 0.0)
    np.testing.assert_array_equal(p.safe, [False, True, True])
    # from a start off the cell centre the same beam misses the corners
    q = BeamPaths(np.array([np.pi / 4]), SPEC, 80.0, 0.37, -0.21)
    assert q.safe[0]


def test_shared_prefix_with_the_previous_beam():
    a = np.array([0.30, 0.31, -2.0])
    p = BeamPaths(a, SPEC, 80.0, 0.0, 0.0)
    for k in (1, 2):
        prev, cur = _cells(p, k - 1), _cells(p, k)
        n = 0
        while n < min(len(prev), len(cur)) and prev[n] == cur[n]:
            n += 1
        assert p.shared[k] == n
    assert p.shared[0] == 0 and p.shared[1] >= 5 and p.shared[2] == 1  # the ego cell only


def test_tables_are_made_when_a_geometry_comes_back():
    angles = np.linspace(-3.0, 3.0, 77)
    spec = GridSpec(20, 24, 0.4)
    assert paths_for(angles, spec, 30.0, 0.1, 0.0) is NO_PATHS  # first sight: walk
    p = paths_for(angles, spec, 30.0, 0.1, 0.0)
    assert isinstance(p, BeamPaths) and p is not NO_PATHS and len(p.safe) == 77
    assert paths_for(angles.copy(), spec, 30.0, 0.1, 0.0) is p  # equal angles: reused
    other = angles.copy()
    other[5] += 1e-3  # same key fields, different angles: not these tables
    assert paths_for(other, spec, 30.0, 0.1, 0.0) is not p
