"""sensor_grid: hand-computed cells, exact traversal, precedence, many rays."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dstenv.dst import SensorState
from dstenv.grid import GridSpec
from dstenv.sensing import sensor_grid

U, F, O = SensorState.UNKNOWN, SensorState.FREE, SensorState.OCCUPIED
SPEC = GridSpec(16, 16, 1.0)  # ego cell (8, 8); cell (i, j) centre x = 8 - i, y = 8 - j


def _cells_crossed(
    spec: GridSpec, x0: float, y0: float, x1: float, y1: float
) -> list[tuple[int, int]]:
    """Reference: cells a segment crosses, from its crossings with every grid line."""
    i0, j0 = spec.ego_cell
    c = spec.cell_size
    ua, va = i0 - x0 / c + 0.5, j0 - y0 / c + 0.5
    ub, vb = i0 - x1 / c + 0.5, j0 - y1 / c + 0.5
    ts = [0.0, 1.0]
    for a, b in ((ua, ub), (va, vb)):
        lo, hi = sorted((a, b))
        for k in range(math.ceil(lo), math.floor(hi) + 1):
            if a != b and 0 < (k - a) / (b - a) < 1:
                ts.append((k - a) / (b - a))
    ts.sort()
    cells = []
    for t0, t1 in zip(ts[:-1], ts[1:]):
        t = (t0 + t1) / 2
        cell = (math.floor(ua + t * (ub - ua)), math.floor(va + t * (vb - va)))
        if not cells or cells[-1] != cell:
            cells.append(cell)
    return cells


def test_single_hit_ray_forward():
    # forward ray hitting at x = 5.2: u = 8 - 5.2 + 0.5 = 3.3 -> row 3
    g = sensor_grid(np.array([0.0]), np.array([5.2]), np.array([True]), SPEC, 80.0)
    expected = np.full(SPEC.shape, U, np.uint8)
    expected[4:9, 8] = F
    expected[3, 8] = O
    np.testing.assert_array_equal(g, expected)


def test_no_return_clears_to_max_range_including_end_cell():
    # left ray (+y) without return, max range 6 m: v = 8 - 6 + 0.5 = 2.5 -> column 2
    g = sensor_grid(np.array([np.pi / 2]), np.array([6.0]), np.array([False]), SPEC, 6.0)
    expected = np.full(SPEC.shape, U, np.uint8)
    expected[8, 2:9] = F
    np.testing.assert_array_equal(g, expected)


def test_hit_beyond_max_range_is_a_clear_ray():
    # a "hit" at 10 m with a 4.2 m sensor: free up to x = 4.2 (u = 8 - 4.2 + 0.5 = 4.3 -> row 4),
    # nothing occupied
    g = sensor_grid(np.array([0.0]), np.array([10.0]), np.array([True]), SPEC, 4.2)
    assert not np.any(g == O)
    np.testing.assert_array_equal(np.flatnonzero(g[:, 8] == F), [4, 5, 6, 7, 8])
    assert np.count_nonzero(g) == 5


def test_ray_leaving_the_grid_stops_at_the_border():
    g = sensor_grid(np.array([np.pi]), np.array([50.0]), np.array([True]), SPEC, 80.0)
    np.testing.assert_array_equal(np.flatnonzero(g[:, 8]), np.arange(8, 16))
    assert np.all(g[8:, 8] == F) and np.count_nonzero(g) == 8


def test_occupied_wins_over_free():
    # ray A ends (hit) in row 5; ray B passes through row 5 without a hit
    g = sensor_grid(np.array([0.0, 0.0]), np.array([3.2, 6.0]), np.array([True, False]), SPEC, 80.0)
    np.testing.assert_array_equal(g[:, 8], [U, U, F, F, F, O, F, F, F, U, U, U, U, U, U, U])
    # order of the rays does not matter
    g2 = sensor_grid(np.array([0.0, 0.0]), np.array([6.0, 3.2]), np.array([False, True]), SPEC,
                     80.0)
    np.testing.assert_array_equal(g, g2)


def test_nan_range_is_skipped():
    g = sensor_grid(np.array([0.0, 1.0]), np.array([np.nan, 3.0]), np.array([False, True]), SPEC,
                    80.0)
    g1 = sensor_grid(np.array([1.0]), np.array([3.0]), np.array([True]), SPEC, 80.0)
    np.testing.assert_array_equal(g, g1)


@pytest.mark.parametrize("origin", [(0.0, 0.0), (0.37, -0.21)])
def test_traversal_matches_exact_reference(origin):
    spec = GridSpec(40, 30, 0.5)
    rng = np.random.default_rng(3)
    for _ in range(200):
        a, r = rng.uniform(-np.pi, np.pi), rng.uniform(0.0, 14.0)
        hit = bool(rng.random() < 0.5)
        g = sensor_grid(np.array([a]), np.array([r]), np.array([hit]), spec, 80.0, origin=origin)
        ox, oy = origin
        crossed = _cells_crossed(spec, ox, oy, ox + r * np.cos(a), oy + r * np.sin(a))
        cells = [(i, j) for i, j in crossed if 0 <= i < spec.height and 0 <= j < spec.width]
        expected = np.zeros(spec.shape, np.uint8)
        for i, j in cells:
            expected[i, j] = F
        end = spec.to_cell(ox + r * np.cos(a), oy + r * np.sin(a))
        if hit and spec.inside(*end):
            expected[end] = O
        np.testing.assert_array_equal(g, expected, err_msg=f"angle {a} range {r} hit {hit}")


def test_many_rays_kitti_like():
    """One ray per point: occupied = the points' cells; the batch equals the union of rays."""
    spec = GridSpec(64, 64, 0.33)
    rng = np.random.default_rng(7)
    n = 3000
    # points on a few "walls" and scattered objects, like a ground-removed scan
    pts = np.concatenate([
        np.stack([rng.uniform(-12, 12, n // 3), np.full(n // 3, 6.3)], 1),
        np.stack([np.full(n // 3, -8.1), rng.uniform(-12, 6.0, n // 3)], 1),
        rng.uniform((-8.0, -15.0), (15.0, 6.0), (n - 2 * (n // 3), 2)),
    ])
    angles, ranges = np.arctan2(pts[:, 1], pts[:, 0]), np.hypot(pts[:, 0], pts[:, 1])
    g = sensor_grid(angles, ranges, np.ones(n, bool), spec, 80.0)
    i, j = spec.to_cell(pts[:, 0], pts[:, 1])
    ok = spec.inside(i, j)
    occ = np.zeros(spec.shape, bool)
    occ[i[ok], j[ok]] = True
    np.testing.assert_array_equal(g == O, occ)
    union = np.zeros(spec.shape, np.uint8)
    for k in range(0, n, 7):  # a subset, ray by ray
        union = np.maximum(union, sensor_grid(angles[k:k + 1], ranges[k:k + 1], [True], spec, 80.0))
    sub = sensor_grid(angles[::7], ranges[::7], np.ones(len(angles[::7]), bool), spec, 80.0)
    np.testing.assert_array_equal(sub, union)
    # no point lies beyond y = 6.3 (v = 32 - 6.3 / 0.33 + 0.5 = 13.4: column 13), so the
    # columns left of it stay unknown, and the wall's own column holds free and occupied
    assert np.all(g[:, :13] == U)
    assert np.any(g[:, 13] == O) and np.any(g[:, 14] == F)


def test_bad_input_is_rejected():
    with pytest.raises(ValueError, match="equal length"):
        sensor_grid(np.zeros(3), np.zeros(2), np.zeros(3, bool), SPEC, 10.0)
    with pytest.raises(ValueError, match="ranges must be >= 0"):
        sensor_grid(np.zeros(1), np.array([-1.0]), np.zeros(1, bool), SPEC, 10.0)
    with pytest.raises(ValueError, match="outside the grid"):
        sensor_grid(np.zeros(1), np.ones(1), np.zeros(1, bool), SPEC, 10.0, origin=(100.0, 0.0))
    with pytest.raises(ValueError, match="max_range"):
        sensor_grid(np.zeros(1), np.ones(1), np.zeros(1, bool), SPEC, 0.0)


def _walk_only(angles, ranges, hit, spec, max_range, origin):
    """The grid of the plain walk (no beam paths), from the kernel itself."""
    from dstenv.sensing import raycast
    from dstenv.sensing.beampaths import NO_PATHS as none

    out = np.zeros(spec.shape, np.uint8)
    raycast._cast(angles, ranges, hit, spec.cell_size, max_range, origin[0], origin[1], out,
                  none.cos, none.sin, none.safe, none.start, none.cells, none.isteps,
                  none.shared)
    return out


def _reference_grid(angles, ranges, hit, spec, max_range, origin):
    """Union of the exact cells of every ray (``_cells_crossed``), occupied ends last."""
    ox, oy = origin
    expected = np.zeros(spec.shape, np.uint8)
    ends = []
    for a, r, h in zip(angles, ranges, hit):
        if np.isnan(r):
            continue
        rr = min(r, max_range)
        end = ox + rr * np.cos(a), oy + rr * np.sin(a)
        cells = _cells_crossed(spec, ox, oy, *end)
        if h and r <= max_range:
            cells = cells[:-1]
            ends.append(spec.to_cell(*end))
        for i, j in cells:
            if not (0 <= i < spec.height and 0 <= j < spec.width):
                break  # the walk stops at the border
            expected[i, j] = F
    for i, j in ends:
        if spec.inside(i, j):
            expected[i, j] = O
    return expected


@pytest.mark.parametrize("origin", [(0.0, 0.0), (0.37, -0.21)])
def test_repeated_beams_use_their_paths_and_stay_exact(origin):
    """A LIDAR's beams come back every sweep: from the second sweep on, each ray
    writes a prefix of its beam's traced path. The grid must stay the exact walk's,
    bit for bit, for hits, clear rays, dropouts, rays leaving the grid, rays ending on
    cell borders and the beams through cell corners (diagonals, axes); and for beams
    off the corners it must be the geometric reference."""
    from dstenv.sensing import beampaths

    spec = GridSpec(40, 30, 0.5)
    rng = np.random.default_rng(11)
    regular = -np.pi + 2 * np.pi / 360 * np.arange(360)  # axes and diagonals included
    generic = rng.uniform(-np.pi, np.pi, 300)
    for angles in (regular, generic):
        n = len(angles)
        for sweep in range(4):
            ranges = rng.uniform(0.0, 16.0, n)
            if sweep == 3:  # end points on cell borders
                ranges = np.round(ranges / 0.25) * 0.25
            ranges[rng.random(n) < 0.1] = np.nan
            hit = rng.random(n) < 0.6
            g = sensor_grid(angles, ranges, hit, spec, 12.0, origin=origin)
            np.testing.assert_array_equal(
                g, _walk_only(angles, ranges, hit, spec, 12.0, origin), err_msg=f"sweep {sweep}")
            if angles is generic and sweep < 3:
                np.testing.assert_array_equal(
                    g, _reference_grid(angles, ranges, hit, spec, 12.0, origin))
        paths = beampaths.paths_for(angles, spec, 12.0, *origin)
        assert np.array_equal(paths.angles, angles)  # traced, and reused
        assert paths.safe.sum() >= n - 8  # at most the corner beams are walked


def test_beam_paths_on_a_grid_of_more_than_65536_cells():
    """Flat cell indices no longer fit uint16: the int32 tables give the walk's grid."""
    from dstenv.sensing import beampaths

    spec = GridSpec(300, 280, 0.3)
    angles = -np.pi + 2 * np.pi / 720 * np.arange(720)
    rng = np.random.default_rng(4)
    for _ in range(3):
        ranges = rng.uniform(0.0, 60.0, 720)
        hit = rng.random(720) < 0.7
        g = sensor_grid(angles, ranges, hit, spec, 50.0, origin=(0.1, 0.0))
        np.testing.assert_array_equal(g, _walk_only(angles, ranges, hit, spec, 50.0, (0.1, 0.0)))
    assert beampaths.paths_for(angles, spec, 50.0, 0.1, 0.0).cells.dtype == np.int32
