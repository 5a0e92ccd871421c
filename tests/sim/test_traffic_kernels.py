"""The traffic kernel's shortcuts give the answers of the plain loops they replace."""

import math

import numpy as np

from dstenv.sim.ego import box_overlap
from dstenv.sim.lanes import heading_trig
from dstenv.sim.traffic import _near_index, _touches


def _touches_all(i, xy, yaw, hl, hw, old_xy, old_yaw):
    """The plain test: every other row (earlier rows at the new, later at the old pose)."""
    for j in range(len(xy)):
        if j == i:
            continue
        jx, jy, jh = (xy[j, 0], xy[j, 1], yaw[j]) if j < i else (old_xy[j, 0], old_xy[j, 1],
                                                                  old_yaw[j])
        if box_overlap(xy[i, 0], xy[i, 1], yaw[i], hl[i], hw[i], jx, jy, jh, hl[j], hw[j]):
            return True
    return False


def test_touches_window_equals_testing_every_row():
    rng = np.random.default_rng(5)
    checked = hits = 0
    for _ in range(60):
        n = int(rng.integers(2, 80))
        old_xy = rng.uniform(0, 60, (n, 2))
        old_yaw = rng.uniform(-np.pi, np.pi, n)
        hl, hw = rng.uniform(0.2, 6.0, n), rng.uniform(0.2, 1.3, n)
        # a step's moves: most rows a little, some a lot (a car at 14 m/s, a respawn)
        move = rng.normal(0, 0.7, (n, 2)) * (rng.random((n, 1)) < 0.8)
        move[rng.random(n) < 0.05] *= 20
        xy, yaw = old_xy + move, old_yaw + rng.normal(0, 0.1, n)
        near = _near_index(xy, old_xy, hl, hw)
        for i in range(n):
            want = _touches_all(i, xy, yaw, hl, hw, old_xy, old_yaw)
            assert _touches(i, xy, yaw, hl, hw, old_xy, old_yaw, near) == want
            checked += 1
            hits += want
    assert checked > 1000 and 100 < hits < checked - 100  # both answers were exercised


def test_heading_trig_is_the_scalar_libm_value():
    h = np.random.default_rng(1).uniform(-4, 4, 500)
    c, s = heading_trig(h)
    assert c.tobytes() == np.array([math.cos(v) for v in h]).tobytes()
    assert s.tobytes() == np.array([math.sin(v) for v in h]).tobytes()
