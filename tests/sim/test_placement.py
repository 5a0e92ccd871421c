"""The numba kernels of map drawing and agent placement against plain references.

The kernels replace Python loops on the reset path (dstenv.sim.placement,
dstenv.sim.kerbside, dstenv.sim.raster); a seed must give the same city and the same
agents as before, so each is checked here against the numpy expression it replaces.
"""

from __future__ import annotations

import numpy as np

from dstenv.sim import World
from dstenv.sim.ego import box_corners, boxes_overlap
from dstenv.sim.kerbside import _arange
from dstenv.sim.lanes import LaneKind
from dstenv.sim.placement import free_spot, near_any, plan_route_nb
from dstenv.sim.raster import fill_rect, fill_rects, paint_where
from dstenv.sim.routing import choose_successor

from .clean import clean_world


def test_free_spot_touching_boxes_are_free_overlapping_ones_are_not():
    # a 4 x 2 m body at the origin; the tested box is length + 2 gap by width + 0.4
    xy, yaw, hl, hw = np.zeros((1, 2)), np.zeros(1), np.array([2.0]), np.array([1.0])
    # gap 0: a 4 x 1.6 m box; centres 8 m apart along x: 2 + 2 = 4 m of room -> free
    assert free_spot(xy, yaw, hl, hw, 1, 8.0, 0.0, 0.0, 4.0, 1.2, 0.0)
    # exactly touching (centres 4 m apart) counts as free, 1 cm closer does not
    assert free_spot(xy, yaw, hl, hw, 1, 4.0, 0.0, 0.0, 4.0, 1.2, 0.0)
    assert not free_spot(xy, yaw, hl, hw, 1, 3.99, 0.0, 0.0, 4.0, 1.2, 0.0)
    # the gap lengthens the tested box: 1 m each way -> needs 5 m
    assert not free_spot(xy, yaw, hl, hw, 1, 4.5, 0.0, 0.0, 4.0, 1.2, 1.0)
    # rows beyond n are not there
    assert free_spot(xy, yaw, hl, hw, 0, 0.0, 0.0, 0.0, 4.0, 1.2, 0.0)


def test_free_spot_agrees_with_the_separating_axis_test_of_ego():
    rng = np.random.default_rng(0)
    n = 40
    xy = rng.uniform(-15, 15, (n, 2))
    yaw, hl, hw = rng.uniform(-np.pi, np.pi, n), rng.uniform(0.3, 3, n), rng.uniform(0.3, 1.2, n)
    for _ in range(300):
        x, y, h = *rng.uniform(-15, 15, 2), rng.uniform(-np.pi, np.pi)
        length, width, gap = rng.uniform(0.5, 6), rng.uniform(0.5, 2.5), rng.uniform(0, 3)
        box = box_corners(x, y, h, length + 2 * gap, width + 0.4)
        others = np.stack([box_corners(*xy[i], yaw[i], 2 * hl[i], 2 * hw[i]) for i in range(n)])
        assert free_spot(xy, yaw, hl, hw, n, x, y, h, length, width, gap) == \
            (not boxes_overlap(box, others).any())


def test_near_any_is_the_distance_matrix_test():
    rng = np.random.default_rng(1)
    q, pts = rng.uniform(0, 50, (60, 2)), rng.uniform(0, 50, (80, 2))
    d = np.hypot(q[:, None, 0] - pts[None, :, 0], q[:, None, 1] - pts[None, :, 1])
    assert np.array_equal(near_any(q, pts, 4.0, False), d.min(1) < 4.0)
    d2 = ((q[:, None, :] - pts[None, :, :]) ** 2).sum(-1)
    assert np.array_equal(near_any(q, pts, 16.0, True), (d2 < 16.0).any(1))
    assert not near_any(q, pts[:0], 4.0, False).any()


def test_plan_route_draws_one_uniform_per_successor():
    net = World(clean_world(), 0).map.lanes
    lane = int(np.flatnonzero(net.kind == LaneKind.ROAD)[0])
    a, b = np.random.default_rng(7), np.random.default_rng(7)
    route = plan_route_nb(lane, np.zeros(0, np.int64), 8, a, net.succ_ptr, net.succ, net.kind,
                          net.turn, 0.4)
    ref = [lane]
    while len(ref) < 8 and ref[-1] >= 0:
        ref.append(choose_successor(ref[-1], b.random(), net.succ_ptr, net.succ, net.kind,
                                    net.turn, 0.4))
    ref += [-1] * (8 - len(ref))
    assert route.tolist() == ref
    assert a.random() == b.random()  # the same number of draws


def test_arange_is_numpy_arange_bit_for_bit():
    rng = np.random.default_rng(2)
    for _ in range(2000):
        a = rng.uniform(0, 50)
        b, step = a + rng.uniform(-5, 300), rng.uniform(0.3, 40)
        assert np.array_equal(_arange(a, b, step), np.arange(a, b, step))


def test_fill_rects_and_paint_where_match_the_plain_versions():
    rng = np.random.default_rng(3)
    boxes = rng.uniform(-2, 22, (50, 4))
    boxes[:, :2].sort(1)
    boxes[:, 2:].sort(1)
    a, b = np.zeros((90, 100), np.uint8), np.zeros((90, 100), np.uint8)
    for box in boxes:
        fill_rect(a, *box, (0.0, 0.0), 0.2, 7)
    fill_rects(b, boxes, (0.0, 0.0), 0.2, 7)
    assert np.array_equal(a, b) and 0 < (a == 7).sum() < a.size
    # one cell: centre (0.1, 0.1) inside [0.05, 0.15]^2, its neighbours' centres not
    one = np.zeros((3, 3), np.uint8)
    fill_rects(one, np.array([[0.05, 0.15, 0.05, 0.15]]), (0.0, 0.0), 0.2, 1)
    assert one.sum() == 1 and one[0, 0] == 1
    src = rng.integers(0, 4, a.shape).astype(np.uint8)
    dst, ref = a.copy(), a.copy()
    paint_where(dst, src, 2, 9)
    ref[src == 2] = 9
    assert np.array_equal(dst, ref)


def test_more_agents_than_the_map_holds_are_said_once_with_the_key(monkeypatch):
    import warnings

    from dstenv.sim import spawn

    monkeypatch.setattr(spawn, "_SHORT_WARNED", set())
    cfg = {"map": {"blocks_x": 1, "blocks_y": 1}, "traffic": {"cars": 400}}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        world = World(cfg, seed=1)
        world.reset(2)  # the same shortfall again: not repeated
    said = [str(w.message) for w in caught if "traffic.cars" in str(w.message)]
    assert len(said) == 1
    placed = int(said[0].split("(")[1].split(" placed")[0])
    assert 0 < placed < 400 and "traffic.cars = 400" in said[0] and "blocks_x" in said[0]
    # a count that fits says nothing
    monkeypatch.setattr(spawn, "_SHORT_WARNED", set())
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        World({"map": {"blocks_x": 1, "blocks_y": 1}, "traffic": {"cars": 3, "cyclists": 0,
                                                                  "pedestrians": 3}}, seed=1)
    assert not [w for w in caught if "does not fit" in str(w.message)]
