"""Numba kernel of :func:`dstenv.sim.clutter.place_clutter`: furniture along block sides.

The placement rules are those documented in :mod:`dstenv.sim.clutter`; this module
runs them for all block sides in one compiled loop, drawing from the city's
``np.random.Generator`` itself (numba draws from the generator's own bit stream in
numpy's order and with numpy's algorithms: uniform, normal, poisson, integers), so
a seed gives the same clutter as the plain Python loop it replaces. ``np.arange``
is reproduced exactly (:func:`_arange`).

Obstacle rows are ``(x, y, yaw, length, width, z_min, z_max, kind)``.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from dstenv.sim.types import ObstacleKind as K

__all__ = ["kerb_clutter"]

# ObstacleKind codes as plain ints (compile-time constants of the kernel)
_POLE, _SIGN, _TREE_TRUNK, _TREE_CROWN = int(K.POLE), int(K.SIGN), int(K.TREE_TRUNK), \
    int(K.TREE_CROWN)
_HEDGE, _FENCE, _BIN, _BOLLARD = int(K.HEDGE), int(K.FENCE), int(K.BIN), int(K.BOLLARD)
_BICYCLE, _SHELTER = int(K.BICYCLE), int(K.SHELTER)


@nb.njit(cache=True)
def _arange(a, b, step):  # pragma: no cover - numba
    """``np.arange(a, b, step)`` of floats, bit for bit (numpy fills ``a + i * d``
    with ``d = (a + step) - a``)."""
    n = int(math.ceil((b - a) / step))
    if n <= 0:
        return np.zeros(0)
    out = np.empty(n)
    out[0] = a
    if n > 1:
        out[1] = a + step
        d = out[1] - a
        for i in range(2, n):
            out[i] = a + i * d
    return out


@nb.njit(cache=True)
def _blocked(x, y, radius, clear, av, sl, c, sn, half_l, half_w):  # pragma: no cover
    """``(x, y)`` nearer than ``clear`` [m] to a crosswalk end ``av (A, 2)``, or (with
    ``radius`` [m]) touching the footprint of a parking slot ``sl (S, >=2)`` (heading
    cosine / sine ``c``, ``sn``, half sizes ``half_l``, ``half_w``)."""
    for i in range(av.shape[0]):
        if math.hypot(av[i, 0] - x, av[i, 1] - y) < clear:
            return True
    for i in range(sl.shape[0]):
        dx, dy = x - sl[i, 0], y - sl[i, 1]
        if not math.hypot(dx, dy) < 5.0:
            continue
        lon = dx * c[i] + dy * sn[i]
        lat = -dx * sn[i] + dy * c[i]
        if abs(lon) < half_l[i] + radius + 0.2 and abs(lat) < half_w[i] + radius + 0.2:
            return True
    return False


@nb.njit(cache=True)
def _put(rows, taken, side, s, lat, half_len, half_wid, z0, z1, kind, yaw_off, check,
         av, sl, c, sn, half_l, half_w):  # pragma: no cover - numba
    """One item at arc length ``s`` and offset ``lat`` [m] of a side ``(start x, y,
    along x, y, inward x, y, length, keep, yaw)``, unless it is off the side, too near
    a ``taken`` item (when ``check``), a crosswalk end or a parked vehicle."""
    length, keep, yaw = side[6], side[7], side[8]
    if not keep <= s <= length - keep:
        return False
    if check:
        for k in range(len(taken)):
            if abs(s - taken[k][0]) < half_len + taken[k][1] + 0.4:
                return False
    x = side[0] + side[2] * s + side[4] * lat
    y = side[1] + side[3] * s + side[5] * lat
    if _blocked(x, y, max(half_len, half_wid), 2.5 + half_len, av, sl, c, sn, half_l, half_w):
        return False
    if check:
        taken.append((s, half_len))
    rows.append((x, y, yaw + yaw_off, 2 * half_len, 2 * half_wid, z0, z1, float(kind)))
    return True


@nb.njit(cache=True)
def _hits_building(side, lo, hi, d0, d1, bbox):  # pragma: no cover - numba
    """The band ``[lo, hi]`` along x ``[d0, d1]`` inward overlaps a building box
    ``bbox (B, 4)`` (x0, y0, x1, y1)."""
    ax = side[0] + side[2] * lo + side[4] * d0
    ay = side[1] + side[3] * lo + side[5] * d0
    bx = side[0] + side[2] * hi + side[4] * d1
    by = side[1] + side[3] * hi + side[5] * d1
    x0, x1 = min(ax, bx) - 0.2, max(ax, bx) + 0.2
    y0, y1 = min(ay, by) - 0.2, max(ay, by) + 0.2
    for i in range(bbox.shape[0]):
        if bbox[i, 0] < x1 and bbox[i, 2] > x0 and bbox[i, 1] < y1 and bbox[i, 3] > y0:
            return True
    return False


@nb.njit(cache=True)
def _within(pts, lo, hi):  # pragma: no cover - numba
    """Rows of ``pts (N, >=2)`` whose first two columns lie in the box ``lo..hi``."""
    keep = np.zeros(pts.shape[0], np.bool_)
    for i in range(pts.shape[0]):
        keep[i] = lo[0] <= pts[i, 0] <= hi[0] and lo[1] <= pts[i, 1] <= hi[1]
    return np.flatnonzero(keep)


@nb.njit(cache=True)
def kerb_clutter(rng, sides, parking, yaws, bbox, slots, slot_c, slot_s, slot_hl, slot_hw,
                 avoid, curb, sidewalk, dens, params):  # pragma: no cover - numba
    """Clutter rows ``(N, 8) float64`` of all block sides (see the module doc).

    Args:
        rng: the city's clutter stream.
        sides: ``(F, 7)`` start x, y, along x, y, inward x, y, length [m].
        parking: ``(F,) bool``; yaws: ``(F,)`` heading of ``along`` [rad].
        bbox: ``(B, 4)`` building boxes; slots ``(S, 6)`` with their heading cosine,
            sine and half sizes; avoid ``(P, 2)`` crosswalk ends.
        curb, sidewalk: kerb strip and sidewalk width [m]; dens: ``density``.
        params: ``(9,)`` pole_spacing, tree_side_prob, tree_spacing, sign_rate,
            bin_rate, bicycle_rate, bollard_prob, shelter_prob, front_prob.
    """
    rows = [(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)]
    rows.pop()
    for f in range(sides.shape[0]):
        length = sides[f, 6]
        keep = curb + sidewalk + 2.0  # clear of the corner's crosswalks and kerb radius
        if length < 2 * keep + 2.0:
            continue
        yaw = yaws[f]
        park = parking[f]
        line = curb + 0.25 if park else curb / 2
        side = np.empty(9)
        side[:7] = sides[f]
        side[7], side[8] = keep, yaw
        lo = np.empty(2)
        hi = np.empty(2)
        for d in range(2):
            end = sides[f, d] + sides[f, 2 + d] * length
            lo[d] = min(sides[f, d], end) - 8.0
            hi[d] = max(sides[f, d], end) + 8.0 + abs(sides[f, 4 + d]) * (curb + sidewalk)
        av = avoid[_within(avoid, lo, hi)]
        k = _within(slots, lo, hi)
        sl, c, sn, hl, hw = slots[k], slot_c[k], slot_s[k], slot_hl[k], slot_hw[k]
        taken = [(0.0, 0.0)]
        taken.pop()
        # poles, then rows of trees, then the rest at random places
        spacing = params[0] / dens
        for s in _arange(keep + rng.uniform(0.0, spacing), length - keep, spacing):
            s2 = s + rng.normal(0.0, 0.1 * spacing)
            _put(rows, taken, side, s2, line, 0.13, 0.13, 0.0, rng.uniform(6.0, 9.0), _POLE,
                 0.0, True, av, sl, c, sn, hl, hw)
        if rng.random() < min(params[1] * dens, 1.0):
            sp = params[2]
            for s in _arange(keep + rng.uniform(0.0, sp), length - keep, sp):
                s = s + rng.uniform(-0.2, 0.2) * sp
                r_trunk = rng.uniform(0.12, 0.25)
                z_crown = rng.uniform(2.0, 3.0)
                if _put(rows, taken, side, s, line, r_trunk, r_trunk, 0.0, z_crown + 0.5,
                        _TREE_TRUNK, 0.0, True, av, sl, c, sn, hl, hw):
                    d = rng.uniform(3.0, 6.5)
                    rows.append((side[0] + side[2] * s + side[4] * line,
                                 side[1] + side[3] * s + side[5] * line, yaw, d, d, z_crown,
                                 z_crown + rng.uniform(3.0, 7.0), float(_TREE_CROWN)))
        per_m = dens * length / 100.0
        for _ in range(rng.poisson(params[3] * per_m)):
            s = rng.uniform(keep, length - keep)
            if _put(rows, taken, side, s, line, 0.05, 0.05, 0.0, 2.3, _SIGN, 0.0, True,
                    av, sl, c, sn, hl, hw):
                rows.append((side[0] + side[2] * s + side[4] * line,
                             side[1] + side[3] * s + side[5] * line, yaw, 0.65, 0.06, 2.0,
                             2.8, float(_SIGN)))
        for _ in range(rng.poisson(params[4] * per_m)):
            big = rng.random() < 0.25  # a container instead of a bin
            _put(rows, taken, side, rng.uniform(keep, length - keep), line,
                 0.6 if big else 0.3, 0.45 if big else 0.3, 0.0, 1.3 if big else 1.0, _BIN,
                 0.0, True, av, sl, c, sn, hl, hw)
        for _ in range(rng.poisson(params[5] * per_m)):
            n = rng.integers(2, 7)
            s0 = rng.uniform(keep, length - keep)
            clear = True
            for t in range(len(taken)):
                if not abs(s0 + 0.95 * n - taken[t][0]) > 0.95 * n + taken[t][1] + 0.4:
                    clear = False
                    break
            if clear:
                for b in range(n):  # one behind the other along the kerb, slightly askew
                    _put(rows, taken, side, s0 + 1.9 * b, line, 0.85, 0.3, 0.0, 1.1, _BICYCLE,
                         rng.normal(0.0, 0.1), False, av, sl, c, sn, hl, hw)
                taken.append((s0 + 0.95 * n, 0.95 * n))
        for end in (keep, length - keep - 6.0):
            if rng.random() < min(params[6] * dens, 1.0):
                for b in range(rng.integers(3, 7)):
                    _put(rows, taken, side, end + 1.2 * b + 0.5,
                         curb + 0.2 if park else curb - 0.3, 0.1, 0.1, 0.0, 0.9, _BOLLARD,
                         0.0, False, av, sl, c, sn, hl, hw)
        if not park and curb > 1.0 and rng.random() < min(params[7] * dens, 1.0):
            _put(rows, taken, side, rng.uniform(keep, length - keep), curb / 2, 2.0,
                 min(0.75, curb / 2 - 0.1), 0.0, 2.5, _SHELTER, 0.0, True, av, sl, c, sn, hl,
                 hw)
        # hedges and fences along the front yards
        front = curb + sidewalk + 0.4
        s = keep - 2.0
        while s < length - keep + 2.0:
            seg = rng.uniform(6.0, 20.0)
            if rng.random() < min(params[8] * dens, 1.0):
                hedge = rng.random() < 0.6
                wid = rng.uniform(0.5, 0.9) if hedge else 0.08
                a, b = s + 0.3, min(s + seg - 0.3, length - keep + 2.0)
                if b - a > 1.5 and not _hits_building(side, a, b, front, front + wid, bbox):
                    mid = (a + b)
                    x = side[0] + side[2] * mid / 2 + side[4] * (front + wid / 2)
                    y = side[1] + side[3] * mid / 2 + side[5] * (front + wid / 2)
                    z1 = rng.uniform(0.8, 1.8) if hedge else rng.uniform(1.0, 1.8)
                    rows.append((x, y, yaw, b - a, wid, 0.0, z1,
                                 float(_HEDGE if hedge else _FENCE)))
            s += seg
    out = np.empty((len(rows), 8))
    for i in range(len(rows)):
        for j in range(8):
            out[i, j] = rows[i][j]
    return out
