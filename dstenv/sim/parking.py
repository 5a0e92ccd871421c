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

__all__ = ["SLOT_LENGTH", "VEHICLE_CLASSES", "CLASS_LO", "CLASS_HI", "side_slots", "draw_vehicles"]

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
    if cfg["parking_layout"] == "lattice":
        n = int((length - 2 * keep_clear) // SLOT_LENGTH)
        if n < 1:
            return np.zeros((0, 6))
        s0 = (length - n * SLOT_LENGTH) / 2
        s = s0 + (np.arange(n) + 0.5) * SLOT_LENGTH
        lat = np.full(n, curb / 2)
        heading = np.full(n, yaw)
        size = np.zeros((n, 3))
        clear = np.full(n, SLOT_LENGTH / 2)
    else:
        mix = np.asarray(cfg["parking_mix"], np.float64)
        cdf = np.cumsum(mix / mix.sum())  # as Generator.choice(4, p=...) builds it
        cdf /= cdf[-1]
        params = np.array([length, keep_clear, curb, sw, cfg["parking_gap_min"],
                           cfg["parking_gap_max"], cfg["parking_lateral_jitter"],
                           cfg["half_on_sidewalk_prob"], np.deg2rad(cfg["parking_heading_jitter"]),
                           yaw, *np.asarray(start, np.float64), *np.asarray(along, np.float64),
                           *np.asarray(inward, np.float64)], np.float64)
        return _irregular(rng, params, cdf, CLASS_LO, CLASS_HI,
                          np.ascontiguousarray(avoid, np.float64).reshape(-1, 2))
    centres = start + along * s[:, None] + inward * lat[:, None]
    if len(avoid):
        need = clear + curb + sw  # [m] least distance of each vehicle to a crosswalk end
        # only the ends within reach of the side matter (a city has thousands)
        lo, hi = centres.min(0) - need.max(), centres.max(0) + need.max()
        avoid = avoid[(avoid[:, 0] >= lo[0]) & (avoid[:, 0] <= hi[0]) &
                      (avoid[:, 1] >= lo[1]) & (avoid[:, 1] <= hi[1])]
    if len(avoid):
        near = np.hypot(avoid[None, :, 0] - centres[:, None, 0],
                        avoid[None, :, 1] - centres[:, None, 1]).min(1)
        ok = near >= need
        centres, heading, size = centres[ok], heading[ok], size[ok]
    return np.column_stack([centres, heading, size]).reshape(-1, 6)


@nb.njit(cache=True)
def _irregular(rng, params, cdf, lo, hi, avoid):  # pragma: no cover - numba
    """``(S, 6)`` rows of the irregular layout along one side (see :func:`side_slots`;
    ``params``: length, keep_clear, curb, sidewalk, gap min / max, lateral jitter,
    half-on-sidewalk probability, heading jitter [rad], yaw, start, along, inward).

    Draws from ``rng`` exactly what the numpy expressions drew, in their order:
    ``draw_vehicles`` (``choice`` with ``p`` = uniforms against the cdf, then the
    sizes), the gaps, the first gap, the side's and the vehicles' lateral offsets,
    the half-on-sidewalk uniforms and their offsets, the heading errors; and the
    same arithmetic element by element (cumulative sums in order)."""
    length, keep_clear, curb, sw = params[0], params[1], params[2], params[3]
    gap_min, gap_max, jit, p_half, h_jit, yaw = (params[4], params[5], params[6], params[7],
                                                params[8], params[9])
    sx, sy, ax, ay, ix, iy = params[10], params[11], params[12], params[13], params[14], \
        params[15]
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
    need = np.empty(n)  # least distance of each vehicle to a crosswalk end [m]
    for k in range(n):
        s = ends[k] - size[k, 0] / 2
        out[k, 0] = sx + ax * s + ix * lat[k]
        out[k, 1] = sy + ay * s + iy * lat[k]
        out[k, 2] = yaw + h_jit * g[k]
        out[k, 3], out[k, 4], out[k, 5] = size[k, 0], size[k, 1], size[k, 2]
        need[k] = size[k, 0] / 2 + curb + sw
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
