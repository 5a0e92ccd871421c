"""Building rows of the procedural city (dstenv.sim.buildings) against the plain loop."""

from __future__ import annotations

import numpy as np
import pytest

from dstenv.sim import default_config
from dstenv.sim.buildings import block_buildings, city_buildings
from dstenv.sim.citygen import _sides


def _reference(face, cfg, rng, side=None):
    """The Python loop the kernel replaces (numpy 2-vectors, rng scalar draws)."""
    front = cfg["curb_strip_width"] + cfg["sidewalk_width"] + 0.3
    x0, x1, y0, y1 = face
    inner = (x0 + front, x1 - front, y0 + front, y1 - front)
    if side is not None:
        inner = tuple(face[k] + (front if k == (2, 1, 3, 0)[side] else 0) *
                      (1 if k in (0, 2) else -1) for k in range(4))
    if inner[1] - inner[0] < 4 or inner[3] - inner[2] < 4:
        return []
    boxes = []
    sides = _sides(inner)
    for si in (rng.permutation(4) if side is None else [side]):
        start, along, inward, length = sides[si]
        depth_room = (inner[3] - inner[2]) if along[0] != 0 else (inner[1] - inner[0])
        setback = rng.uniform(cfg["setback_min"], cfg["setback_max"])
        room = depth_room / 2 - setback if side is None else depth_room - setback - 2.0
        pos = 0.0
        while pos < length - cfg["building_width_min"]:
            w = min(rng.uniform(cfg["building_width_min"], cfg["building_width_max"]),
                    length - pos)
            d = min(rng.uniform(cfg["building_depth_min"], cfg["building_depth_max"]), room)
            sb = setback + rng.uniform(0, 0.6)
            if rng.random() < cfg["building_coverage"] and d > 3.0:
                a = start + along * pos + inward * sb
                b = start + along * (pos + w) + inward * (sb + d)
                box = (min(a[0], b[0]), max(a[0], b[0]), min(a[1], b[1]), max(a[1], b[1]))
                if all(min(box[1], o[1]) - max(box[0], o[0]) <= 0.3 or
                       min(box[3], o[3]) - max(box[2], o[2]) <= 0.3 for o in boxes):
                    boxes.append(box)
            pos += w
            if rng.random() < cfg["gap_prob"]:
                pos += rng.uniform(cfg["gap_min"], cfg["gap_max"])
    return [np.array([[b[0], b[2]], [b[1], b[2]], [b[1], b[3]], [b[0], b[3]]]) for b in boxes]


@pytest.mark.parametrize("side", [None, 0, 1, 2, 3])
def test_rows_equal_the_plain_loop_bit_for_bit(side):
    cfg = default_config()["map"]
    cfg = {**cfg, "gap_prob": 0.5, "building_width_min": 3.0}  # many short buildings
    layout = np.random.default_rng(1)
    for k in range(40):
        x0, y0 = layout.uniform(0, 300, 2)
        face = (x0, x0 + layout.uniform(5, 160), y0, y0 + layout.uniform(5, 160))
        got = block_buildings(face, cfg, r1 := np.random.default_rng(k), side)
        ref = _reference(face, cfg, r2 := np.random.default_rng(k), side)
        assert len(got) == len(ref)
        assert all(np.array_equal(a, b) for a, b in zip(got, ref))
        assert r1.random() == r2.random()  # the same number of draws
    # buildings of one block never overlap by more than 0.3 m
    boxes = block_buildings((0.0, 120.0, 0.0, 90.0), cfg, np.random.default_rng(7), side)
    assert len(boxes) > 3
    lo, hi = np.array([b.min(0) for b in boxes]), np.array([b.max(0) for b in boxes])
    over = np.minimum(hi[:, None], hi[None]) - np.maximum(lo[:, None], lo[None])
    both = (over > 0.3).all(-1)
    assert not both[~np.eye(len(boxes), dtype=bool)].any()


def test_city_buildings_equal_the_blocks_one_after_the_other():
    cfg = default_config()["map"]
    layout = np.random.default_rng(2)
    boxes = [(x, x + layout.uniform(3, 150), y, y + layout.uniform(3, 150))
             for x, y in layout.uniform(0, 500, (40, 2))]
    sides = [-1] * 30 + [0, 1, 2, 3, 0, 1, 2, 3, 2, 1]
    got = city_buildings(boxes, sides, cfg, r1 := np.random.default_rng(11))
    r2 = np.random.default_rng(11)
    ref = [b for box, side in zip(boxes, sides)
           for b in _reference(box, cfg, r2, None if side < 0 else side)]
    assert len(got) == len(ref) > 100
    assert all(np.array_equal(a, b) for a, b in zip(got, ref))
    assert r1.random() == r2.random()
