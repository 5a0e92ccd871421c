"""Kerbside parking of the procedural city: where parked vehicles stand, and which.

Two layouts (``world.map.parking_layout``):

* ``"lattice"``: the ideal world of the ``clean`` scenario: slots exactly
  :data:`SLOT_LENGTH` apart, centred in the kerb strip, aligned with the kerb; the
  vehicle size is drawn later by the spawner (one car size).
* ``"irregular"``: vehicles placed one after the other along the kerb with a drawn
  gap between them, a vehicle class from ``parking_mix`` (small car, car, van,
  truck), a lateral offset per street side plus one per vehicle, a heading error per
  vehicle, and now and then a car parked half on the sidewalk. Empty stretches come
  from ``traffic.parked_density`` (a slot is occupied with that probability).

Every slot is a row ``(x, y, yaw, length, width, height)`` [m, rad]; ``length = 0``
(lattice) lets the spawner draw a car size.
"""

from __future__ import annotations

from typing import Any

import numba as nb
import numpy as np

__all__ = ["SLOT_LENGTH", "VEHICLE_CLASSES", "CLASS_LO", "CLASS_HI", "side_slots", "draw_vehicles",
           "city_slots"]

SLOT_LENGTH = 6.0  # [m] length of one kerbside parking slot (lattice layout)

#: vehicle classes of ``parking_mix`` / ``traffic.vehicle_mix``: name -> (length range,
#: width range, height range) [m]
VEHICLE_CLASSES: dict[str, tuple[tuple[float, float], tuple[float, float], tuple[float, float]]] = {
    "small": ((3.4, 3.9), (1.6, 1.72), (1.4, 1.55)),
    "car": ((4.0, 4.9), (1.72, 1.95), (1.4, 1.65)),
    "van": ((4.9, 6.2), (1.9, 2.1), (2.0, 2.6)),
    "truck": ((6.5, 8.5), (2.3, 2.5), (3.0, 3.5)),
}
_NAMES = tuple(VEHICLE_CLASSES)
#: ``(4, 3)`` lower and upper bounds of length, width, height per class [m]
CLASS_LO = np.array([[VEHICLE_CLASSES[k][d][0] for d in range(3)] for k in _NAMES])
CLASS_HI = np.array([[VEHICLE_CLASSES[k][d][1] for d in range(3)] for k in _NAMES])


def draw_vehicles(mix: list[float] | tuple[float, ...], n: int,
                  rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Vehicle classes and sizes from a mix.

    Args:
        mix: ``(4,)`` non-negative weights of small car, car, van, truck.
        n: number of vehicles.

    Returns:
        ``cls (n,) int64`` index into :data:`VEHICLE_CLASSES` and ``size (n, 3)
        float64`` length, width, height [m].
    """
    p = np.asarray(mix, np.float64)
    cls = rng.choice(len(_NAMES), size=n, p=p / p.sum())
    size = CLASS_LO[cls] + rng.random((n, 3)) * (CLASS_HI[cls] - CLASS_LO[cls])
    return cls, size


def side_slots(start: np.ndarray, along: np.ndarray, inward: np.ndarray, length: float,
               cfg: dict[str, Any], rng: np.random.Generator, avoid: np.ndarray
               ) -> np.ndarray:
    """Parking positions along one block side.

    Args:
        start, along, inward: the side's kerb start point, unit direction along the
            kerb and unit normal into the block (world frame).
        length: kerb length [m].
        cfg: the ``world.map`` section.
        avoid: ``(K, 2)`` crosswalk ends; no vehicle stands across them.

    Returns:
        ``(S, 6) float64`` rows ``x, y, yaw, length, width, height`` (see module doc).
    """
    curb, sw = cfg["curb_strip_width"], cfg["sidewalk_width"]
    keep_clear = curb + sw + 10.0  # [m] no parking near junctions (crosswalks, turns)
    yaw = float(np.arctan2(-along[1], -along[0]))  # with the adjacent traffic (right-hand)
    params = np.array([length, keep_clear, curb, sw, cfg["parking_gap_min"],
                       cfg["parking_gap_max"], cfg["parking_lateral_jitter"],
                       cfg["half_on_sidewalk_prob"], np.deg2rad(cfg["parking_heading_jitter"]),
                       yaw, *np.asarray(start, np.float64), *np.asarray(along, np.float64),
                       *np.asarray(inward, np.float64)], np.float64)
    avoid = np.ascontiguousarray(avoid, np.float64).reshape(-1, 2)
    if cfg["parking_layout"] == "lattice":
        return _lattice(params, avoid)
    mix = np.asarray(cfg["parking_mix"], np.float64)
    cdf = np.cumsum(mix / mix.sum())  # as Generator.choice(4, p=...) builds it
    cdf /= cdf[-1]
    return _irregular(rng, params, cdf, CLASS_LO, CLASS_HI, avoid)


@nb.njit(cache=True)
def block_side(x0, x1, y0, y1, k):
    """Side ``k`` (0-3, counter-clockwise from the bottom) of the block ``x0..x1 x
    y0..y1``: ``(start x, start y, along x, along y, inward x, inward y, length)``, as
    ``citygen._sides`` lists them."""
    if k == 0:
        return x0, y0, 1.0, 0.0, 0.0, 1.0, x1 - x0
    if k == 1:
        return x1, y0, 0.0, 1.0, -1.0, 0.0, y1 - y0
    if k == 2:
        return x1, y1, -1.0, 0.0, 0.0, -1.0, x1 - x0
    return x0, y1, 0.0, -1.0, 1.0, 0.0, y1 - y0


@nb.njit(cache=True)
def _irregular(rng, params, cdf, lo, hi, avoid):  # pragma: no cover - numba
    """``(S, 6)`` rows of the irregular layout along one side (see :func:`side_slots`;
    ``params``: length, keep_clear, curb, sidewalk, gap min / max, lateral jitter,
    half-on-sidewalk probability, heading jitter [rad], yaw, start, along, inward;
    the centres and the crosswalk test by :func:`_place`).

    Draws from ``rng`` exactly what the numpy expressions drew, in their order:
    ``draw_vehicles`` (``choice`` with ``p`` = uniforms against the cdf, then the
    sizes), the gaps, the first gap, the side's and the vehicles' lateral offsets,
    the half-on-sidewalk uniforms and their offsets, the heading errors; and the
    same arithmetic element by element (cumulative sums in order)."""
    length, keep_clear, curb, sw = params[0], params[1], params[2], params[3]
    gap_min, gap_max, jit, p_half, h_jit, yaw = (params[4], params[5], params[6], params[7],
                                                params[8], params[9])
    room = length - keep_clear
    m = max(int((room - keep_clear) / 4.0) + 1, 1)
    u = rng.random(m)
    size = np.empty((m, 3))
    r3 = rng.random((m, 3))
    for k in range(m):
        c = np.searchsorted(cdf, u[k], side="right")
        for d in range(3):
            size[k, d] = lo[c, d] + r3[k, d] * (hi[c, d] - lo[c, d])
    gap = rng.uniform(gap_min, gap_max, m)
    first = keep_clear + rng.uniform(0.0, gap_max)
    ends = np.empty(m)
    acc = 0.0
    for k in range(m):
        acc += size[k, 0] + gap[k]
        ends[k] = first + acc - gap[k]
    n = np.searchsorted(ends, room, side="right")
    if n == 0:
        return np.zeros((0, 6))
    side_off = rng.uniform(-jit, jit)
    z = rng.normal(0.0, jit / 2, n)
    lat = np.empty(n)
    for k in range(n):
        half_w = size[k, 1] / 2
        lat[k] = min(max(curb / 2 + side_off + z[k], half_w - 0.1),
                     max(curb - half_w + 0.1, half_w - 0.1))
    uh = rng.random(n)
    n_on = 0
    for k in range(n):
        if uh[k] < p_half and size[k, 0] < 5.0 and sw > 1.8:
            n_on += 1
    on = rng.uniform(-0.2, 0.1, n_on)
    j = 0
    for k in range(n):
        if uh[k] < p_half and size[k, 0] < 5.0 and sw > 1.8:
            lat[k] = curb + on[j]
            j += 1
    g = rng.standard_normal(n)
    out = np.empty((n, 6))
    s = np.empty(n)
    clear = np.empty(n)
    for k in range(n):
        s[k] = ends[k] - size[k, 0] / 2
        clear[k] = size[k, 0] / 2
        out[k, 2] = yaw + h_jit * g[k]
        out[k, 3], out[k, 4], out[k, 5] = size[k, 0], size[k, 1], size[k, 2]
    return _place(params, out, s, lat, clear, avoid)


def city_slots(boxes: list[tuple[float, float, float, float]], sides: list[tuple[int, ...]],
               cfg: dict[str, Any], rng: np.random.Generator, avoid: np.ndarray
               ) -> tuple[np.ndarray, list[tuple[int, int]], np.ndarray]:
    """Parking along the sides of all blocks of a city, in one call.

    For each box (block ``x0, x1, y0, y1`` [m] at the kerb) and each of its ``sides``
    (0..3: bottom, right, top, left, as ``citygen._sides``) long enough for a slot
    clear of the junctions, one uniform decides (``map.parking_prob``) whether the
    side has a parking strip, then :func:`side_slots` places its vehicles: the draws
    and results of calling them one side after the other.

    Returns:
        ``slots (S, 6) float64`` (see module doc), the ``(box index, side)`` of each
        side with a strip, and ``strips (S, 4) float64`` the rectangles ``x_lo, x_hi,
        y_lo, y_hi`` [m] each slot covers across the kerb strip (painted as parking).
    """
    ptr = np.cumsum([0] + [len(k) for k in sides]).astype(np.int64)
    side_k = np.array([k for ks in sides for k in ks], np.int64)
    mix = np.asarray(cfg["parking_mix"], np.float64)
    cdf = np.cumsum(mix / mix.sum())  # as Generator.choice(4, p=...) builds it
    cdf /= cdf[-1]
    params = np.array([cfg["curb_strip_width"], cfg["sidewalk_width"], cfg["parking_gap_min"],
                       cfg["parking_gap_max"], cfg["parking_lateral_jitter"],
                       cfg["half_on_sidewalk_prob"], np.deg2rad(cfg["parking_heading_jitter"]),
                       cfg["parking_prob"], float(cfg["parking_layout"] == "lattice")],
                      np.float64)
    slots, side_of, strips = _city(rng, np.asarray(boxes, np.float64).reshape(-1, 4), ptr, side_k,
                                   params, cdf, CLASS_LO, CLASS_HI,
                                   np.ascontiguousarray(avoid, np.float64).reshape(-1, 2))
    parked = [(int(b), int(k)) for b, k in side_of]
    return slots, parked, strips


@nb.njit(cache=True)
def _city(rng, boxes, ptr, side_k, params, cdf, lo, hi, avoid):  # pragma: no cover - numba
    """:func:`city_slots`: rows of all sides, ``(box, side)`` of the sides with a strip,
    and the painted rectangle of every row."""
    curb, sw, p_park, lattice = params[0], params[1], params[7], params[8] > 0
    keep_clear = curb + sw + 10.0
    rows = np.empty((256, 6))
    strips = np.empty((256, 4))
    side_of = np.empty((64, 2), np.int64)
    n_rows, n_sides = 0, 0
    one = np.empty(16)
    for b in range(boxes.shape[0]):
        x0, x1, y0, y1 = boxes[b, 0], boxes[b, 1], boxes[b, 2], boxes[b, 3]
        for i in range(ptr[b], ptr[b + 1]):
            k = side_k[i]
            sx, sy, ax, ay, ix, iy, length = block_side(x0, x1, y0, y1, k)
            if int((length - 2 * keep_clear) // SLOT_LENGTH) < 1 or rng.random() >= p_park:
                continue
            one[0], one[1], one[2], one[3] = length, keep_clear, curb, sw
            one[4:9] = params[2:7]
            one[9] = np.arctan2(-ay, -ax)  # with the adjacent traffic (right-hand)
            one[10], one[11], one[12], one[13], one[14], one[15] = sx, sy, ax, ay, ix, iy
            got = _lattice(one, avoid) if lattice else _irregular(rng, one, cdf, lo, hi, avoid)
            if n_sides == side_of.shape[0]:
                grown = np.empty((2 * n_sides, 2), np.int64)
                grown[:n_sides] = side_of
                side_of = grown
            side_of[n_sides, 0], side_of[n_sides, 1] = b, k
            n_sides += 1
            while n_rows + got.shape[0] > rows.shape[0]:
                rows2, strips2 = np.empty((2 * rows.shape[0], 6)), np.empty((2 * rows.shape[0], 4))
                rows2[:n_rows], strips2[:n_rows] = rows[:n_rows], strips[:n_rows]
                rows, strips = rows2, strips2
            for j in range(got.shape[0]):
                rows[n_rows] = got[j]
                # across the kerb strip: c -/+ along * half -/+ inward * curb / 2
                half = (got[j, 3] if got[j, 3] != 0 else SLOT_LENGTH) / 2
                a0 = got[j, 0] - ax * half - ix * curb / 2
                a1 = got[j, 1] - ay * half - iy * curb / 2
                b0 = got[j, 0] + ax * half + ix * curb / 2
                b1 = got[j, 1] + ay * half + iy * curb / 2
                strips[n_rows, 0], strips[n_rows, 1] = min(a0, b0), max(a0, b0)
                strips[n_rows, 2], strips[n_rows, 3] = min(a1, b1), max(a1, b1)
                n_rows += 1
    return rows[:n_rows].copy(), side_of[:n_sides].copy(), strips[:n_rows].copy()


@nb.njit(cache=True)
def _lattice(params, avoid):  # pragma: no cover - numba
    """``(S, 6)`` rows of the lattice layout along one side (``params`` as for
    :func:`_irregular`): slots :data:`SLOT_LENGTH` apart, centred in the kerb strip."""
    length, keep_clear, curb, yaw = params[0], params[1], params[2], params[9]
    n = int((length - 2 * keep_clear) // SLOT_LENGTH)
    if n < 1:
        return np.zeros((0, 6))
    s0 = (length - n * SLOT_LENGTH) / 2
    s = np.empty(n)
    for k in range(n):
        s[k] = s0 + (k + 0.5) * SLOT_LENGTH
    out = np.zeros((n, 6))
    out[:, 2] = yaw
    return _place(params, out, s, np.full(n, curb / 2), np.full(n, SLOT_LENGTH / 2), avoid)


@nb.njit(cache=True)
def _place(params, out, s, lat, clear, avoid):  # pragma: no cover - numba
    """Centres ``start + along * s + inward * lat`` into ``out[:, :2]``; the rows of
    vehicles at least ``clear + curb + sidewalk`` from every crosswalk end."""
    curb, sw = params[2], params[3]
    sx, sy, ax, ay, ix, iy = params[10], params[11], params[12], params[13], params[14], \
        params[15]
    n = out.shape[0]
    need = np.empty(n)  # least distance of each vehicle to a crosswalk end [m]
    for k in range(n):
        out[k, 0] = sx + ax * s[k] + ix * lat[k]
        out[k, 1] = sy + ay * s[k] + iy * lat[k]
        need[k] = clear[k] + curb + sw
    # only the ends within reach of the side matter (a city has thousands)
    reach = need.max()
    x_lo, x_hi = out[:, 0].min() - reach, out[:, 0].max() + reach
    y_lo, y_hi = out[:, 1].min() - reach, out[:, 1].max() + reach
    near = np.empty(avoid.shape[0], np.int64)
    n_near = 0
    for q in range(avoid.shape[0]):
        if x_lo <= avoid[q, 0] <= x_hi and y_lo <= avoid[q, 1] <= y_hi:
            near[n_near] = q
            n_near += 1
    keep = np.ones(n, np.bool_)
    for k in range(n):
        for i in range(n_near):
            q = near[i]
            if np.hypot(avoid[q, 0] - out[k, 0], avoid[q, 1] - out[k, 1]) < need[k]:
                keep[k] = False
                break
    return out[keep]
