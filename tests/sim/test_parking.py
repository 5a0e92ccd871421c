"""Kerbside parking (dstenv.sim.parking): the numba irregular layout against the numpy
expressions it replaces, bit for bit and draw for draw."""

from __future__ import annotations

import numpy as np
import pytest

from dstenv.sim import default_config
from dstenv.sim.parking import SLOT_LENGTH, city_slots, draw_vehicles, side_slots
from dstenv.sim.citygen import _sides


def _reference(start, along, inward, length, cfg, rng, avoid):
    """The irregular layout as numpy expressions (the former implementation)."""
    curb, sw = cfg["curb_strip_width"], cfg["sidewalk_width"]
    keep_clear = curb + sw + 10.0
    yaw = float(np.arctan2(-along[1], -along[0]))
    room = length - keep_clear
    m = max(int((room - keep_clear) / 4.0) + 1, 1)
    _, size = draw_vehicles(cfg["parking_mix"], m, rng)
    gap = rng.uniform(cfg["parking_gap_min"], cfg["parking_gap_max"], m)
    first = keep_clear + rng.uniform(0.0, cfg["parking_gap_max"])
    ends = first + np.cumsum(size[:, 0] + gap) - gap
    n = int(np.searchsorted(ends, room, side="right"))
    if n == 0:
        return np.zeros((0, 6))
    size = size[:n]
    s = ends[:n] - size[:, 0] / 2
    jit = cfg["parking_lateral_jitter"]
    lat = curb / 2 + rng.uniform(-jit, jit) + rng.normal(0.0, jit / 2, n)
    lat = np.clip(lat, size[:, 1] / 2 - 0.1, np.maximum(curb - size[:, 1] / 2 + 0.1,
                                                       size[:, 1] / 2 - 0.1))
    half_on = (rng.random(n) < cfg["half_on_sidewalk_prob"]) & (size[:, 0] < 5.0) & (sw > 1.8)
    lat[half_on] = curb + rng.uniform(-0.2, 0.1, int(half_on.sum()))
    heading = yaw + np.deg2rad(cfg["parking_heading_jitter"]) * rng.standard_normal(n)
    centres = start + along * s[:, None] + inward * lat[:, None]
    if len(avoid):
        near = np.hypot(avoid[None, :, 0] - centres[:, None, 0],
                        avoid[None, :, 1] - centres[:, None, 1]).min(1)
        ok = near >= size[:, 0] / 2 + curb + sw
        centres, heading, size = centres[ok], heading[ok], size[ok]
    return np.column_stack([centres, heading, size]).reshape(-1, 6)


def test_irregular_layout_equals_the_numpy_expressions():
    base = default_config()["map"]
    layout = np.random.default_rng(0)
    dropped = 0
    for t in range(120):
        cfg = {**base, "half_on_sidewalk_prob": (0.08, 0.6, 0.0)[t % 3],
               "parking_lateral_jitter": 0.0 if t % 5 == 2 else 0.3}
        ang = layout.uniform(0, 2 * np.pi)
        along = np.array([np.cos(ang), np.sin(ang)])
        inward = np.array([-along[1], along[0]])
        start, length = layout.uniform(-100, 100, 2), layout.uniform(10, 150)
        avoid = layout.uniform(-150, 150, (int(layout.integers(0, 200)), 2))
        got = side_slots(start, along, inward, length, cfg, r1 := np.random.default_rng(t), avoid)
        ref = _reference(start, along, inward, length, cfg, r2 := np.random.default_rng(t), avoid)
        assert got.shape == ref.shape and np.array_equal(got, ref)
        assert r1.random() == r2.random()  # the same number of draws
        no_avoid = side_slots(start, along, inward, length, cfg, np.random.default_rng(t),
                              np.zeros((0, 2)))
        dropped += len(no_avoid) - len(got)
    assert dropped > 20  # crosswalk ends did remove vehicles


def _lattice_reference(start, along, inward, length, cfg, avoid):
    curb, sw = cfg["curb_strip_width"], cfg["sidewalk_width"]
    keep_clear = curb + sw + 10.0
    n = int((length - 2 * keep_clear) // SLOT_LENGTH)
    if n < 1:
        return np.zeros((0, 6))
    s = (length - n * SLOT_LENGTH) / 2 + (np.arange(n) + 0.5) * SLOT_LENGTH
    centres = start + along * s[:, None] + inward * np.full(n, curb / 2)[:, None]
    heading = np.full(n, float(np.arctan2(-along[1], -along[0])))
    ok = np.ones(n, bool)
    if len(avoid):
        ok = np.hypot(avoid[None, :, 0] - centres[:, None, 0],
                      avoid[None, :, 1] - centres[:, None, 1]).min(1) >= SLOT_LENGTH / 2 + curb + sw
    return np.column_stack([centres[ok], heading[ok], np.zeros((ok.sum(), 3))])


@pytest.mark.parametrize("layout", ["irregular", "lattice"])
def test_city_slots_equal_the_side_by_side_loop(layout):
    """All sides of all blocks in one call: the same slots, sides, strip rectangles
    and draws as the per-side loop (a uniform per long side, then its vehicles)."""
    cfg = {**default_config()["map"], "parking_layout": layout, "parking_prob": 0.6}
    layout_rng = np.random.default_rng(3)
    boxes = [(x, x + layout_rng.uniform(20, 120), y, y + layout_rng.uniform(20, 120))
             for x, y in layout_rng.uniform(0, 400, (30, 2))]
    sides = [(0, 1, 2, 3)] * 25 + [(k,) for k in (0, 1, 2, 3, 2)]
    avoid = layout_rng.uniform(0, 500, (300, 2))
    slots, parked, strips = city_slots(boxes, sides, cfg, r1 := np.random.default_rng(5), avoid)
    r2 = np.random.default_rng(5)
    curb, sw = cfg["curb_strip_width"], cfg["sidewalk_width"]
    ref_rows, ref_parked, ref_strips = [], [], []
    for b, (box, ks) in enumerate(zip(boxes, sides)):
        for k in ks:
            start, along, inward, length = _sides(box)[k]
            if int((length - 2 * (curb + sw + 10.0)) // SLOT_LENGTH) < 1 or \
                    r2.random() >= cfg["parking_prob"]:
                continue
            rows = side_slots(start, along, inward, length, cfg, r2, avoid)
            if layout == "lattice":
                assert np.array_equal(rows, _lattice_reference(start, along, inward, length,
                                                               cfg, avoid))
            ref_parked.append((b, k))
            half = (np.where(rows[:, 3] != 0, rows[:, 3], SLOT_LENGTH) / 2)[:, None]
            a = rows[:, :2] - along * half - inward * curb / 2
            c = rows[:, :2] + along * half + inward * curb / 2
            ref_strips.append(np.stack([np.minimum(a[:, 0], c[:, 0]), np.maximum(a[:, 0], c[:, 0]),
                                        np.minimum(a[:, 1], c[:, 1]),
                                        np.maximum(a[:, 1], c[:, 1])], -1))
            ref_rows.append(rows)
    assert parked == ref_parked and len(parked) > 20
    assert np.array_equal(slots, np.concatenate(ref_rows))
    assert np.array_equal(strips, np.concatenate(ref_strips))
    assert r1.random() == r2.random()
