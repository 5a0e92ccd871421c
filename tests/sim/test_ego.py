"""Ego footprint tests: oriented-box overlap, collision and off-road flags."""

import numpy as np
import pytest

from dstenv.sim.ego import box_corners, box_overlap, boxes_overlap, hits

from .handmade import BLOCK, LW, cross_map

NONE = (np.zeros((0, 2)), np.zeros(0), np.zeros(0), np.zeros(0))


@pytest.mark.parametrize("dx, dy, yaw2, expected", [
    (4.0, 0.0, 0.0, True),  # 4.5 m boxes 4 m apart along x overlap
    (4.6, 0.0, 0.0, False),
    (0.0, 1.8, 0.0, True),  # 2 m wide boxes 1.8 m apart sideways
    (0.0, 2.1, 0.0, False),
    (3.2, 0.0, np.pi / 2, True),  # perpendicular: reach 2.25 + 1.0 = 3.25 along x
    (3.3, 0.0, np.pi / 2, False),
])
def test_box_overlap_by_hand(dx, dy, yaw2, expected):
    assert box_overlap(0.0, 0.0, 0.0, 2.25, 1.0, dx, dy, yaw2, 2.25, 1.0) == expected
    a = box_corners(0.0, 0.0, 0.0, 4.5, 2.0)
    b = box_corners(dx, dy, yaw2, 4.5, 2.0)
    assert boxes_overlap(a, b[None])[0] == expected


def test_flags_on_a_hand_built_map():
    m = cross_map()
    on_lane = (20.0, -LW / 2, 0.0, 4.5, 1.9)
    assert hits(m, *NONE, on_lane) == (False, False)
    on_kerb = (20.0, -LW + 0.5, 0.0, 4.5, 1.9)  # right side over the kerb
    assert hits(m, *NONE, on_kerb) == (False, True)
    inside = sum(BLOCK) / 2
    assert hits(m, *NONE, (inside, inside, 0.3, 4.5, 1.9)) == (True, True)
    other = (np.array([[22.0, -LW / 2]]), np.zeros(1), np.array([2.25]), np.array([0.95]))
    assert hits(m, *other, on_lane) == (True, False)
