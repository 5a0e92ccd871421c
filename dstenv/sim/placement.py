"""Numba kernels of agent placement: the free-spot test and moving agents on lanes.

:func:`dstenv.sim.spawn.populate` places ~150 agents per episode, one after the
other (each must be clear of those before it). These kernels do the whole loop in
compiled code, drawing from the episode's ``np.random.Generator`` itself (numba
draws from the generator's own bit stream, in the same order and with the same
algorithms as numpy), so a seed gives the same agents as the plain Python loop
it replaces:

per agent: length and width (2 uniforms), for cars with a ``vehicle_mix`` the class
(1 uniform) and its length, width, height (3 uniforms); the desired speed factors of
car, cyclist and pedestrian (3 uniforms, one kept); then up to 30 tries of: a lane
(1 uniform, by length) when none is given, the arc length (1 uniform) when none is
given, the free-spot test; on success the route (one uniform per successor) and the
initial speed factor (1 uniform).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from dstenv.sim.lanes import lane_pose
from dstenv.sim.routing import choose_successor

__all__ = ["free_spot", "near_any", "plan_route_nb", "place_mobile", "TRIES"]

TRIES = 30  # attempts per agent to find a free lane position


@nb.njit(cache=True)
def free_spot(xy, yaw, hl, hw, n, x, y, h, length, width, gap):  # pragma: no cover - numba
    """No body among the first ``n`` rows (``xy (N, 2)``, ``yaw``, half length ``hl``
    and width ``hw`` [m, rad]) overlaps the box at ``(x, y, h)`` of ``length + 2 gap``
    by ``width + 0.4`` [m] (separating axes, touching within 1e-9 m counts as free)."""
    bl, bw = length + 2.0 * gap, width + 0.4
    c, s = math.cos(h), math.sin(h)
    box = np.empty((4, 2))
    oth = np.empty((4, 2))
    for i, (lx, ly) in enumerate(((bl, bw), (-bl, bw), (-bl, -bw), (bl, -bw))):
        lx, ly = lx / 2.0, ly / 2.0
        box[i, 0] = lx * c - ly * s + x
        box[i, 1] = lx * s + ly * c + y
    reach = 0.5 * math.hypot(bl, bw)
    axes = np.empty((4, 2))
    axes[0, 0], axes[0, 1] = box[1, 0] - box[0, 0], box[1, 1] - box[0, 1]
    axes[1, 0], axes[1, 1] = box[2, 0] - box[1, 0], box[2, 1] - box[1, 1]
    for j in range(n):
        # only bodies that can touch the box (half diagonals + margin)
        if math.hypot(xy[j, 0] - x, xy[j, 1] - y) > reach + math.hypot(hl[j], hw[j]) + 0.1:
            continue
        cj, sj = math.cos(yaw[j]), math.sin(yaw[j])
        for i, (lx, ly) in enumerate(((hl[j], hw[j]), (-hl[j], hw[j]), (-hl[j], -hw[j]),
                                      (hl[j], -hw[j]))):
            oth[i, 0] = cj * lx + -sj * ly + xy[j, 0]
            oth[i, 1] = sj * lx + cj * ly + xy[j, 1]
        axes[2, 0], axes[2, 1] = oth[1, 0] - oth[0, 0], oth[1, 1] - oth[0, 1]
        axes[3, 0], axes[3, 1] = oth[2, 0] - oth[1, 0], oth[2, 1] - oth[1, 1]
        separated = False
        for a in range(4):
            pa_lo, pa_hi, pb_lo, pb_hi = np.inf, -np.inf, np.inf, -np.inf
            for i in range(4):
                pa = axes[a, 0] * box[i, 0] + axes[a, 1] * box[i, 1]
                pb = axes[a, 0] * oth[i, 0] + axes[a, 1] * oth[i, 1]
                pa_lo, pa_hi = min(pa_lo, pa), max(pa_hi, pa)
                pb_lo, pb_hi = min(pb_lo, pb), max(pb_hi, pb)
            if pa_hi <= pb_lo + 1e-9 or pb_hi <= pa_lo + 1e-9:
                separated = True
                break
        if not separated:
            return False
    return True


@nb.njit(cache=True)
def plan_route_nb(lane, fixed, k, rng, succ_ptr, succ, lkind, turn, cross_prob
                  ):  # pragma: no cover - numba
    """``(k,) int64`` route: ``lane``, then ``fixed``, then random successors (one
    uniform each) until ``k`` lanes or a dead end (-1)."""
    route = np.full(k, -1, np.int64)
    route[0] = lane
    m = min(fixed.shape[0], k - 1)
    route[1:1 + m] = fixed[:m]
    for i in range(1 + m, k):
        if route[i - 1] < 0:
            break
        route[i] = choose_successor(route[i - 1], rng.random(), succ_ptr, succ, lkind, turn,
                                    cross_prob)
    return route


@nb.njit(cache=True)
def place_mobile(rng, count, kind, body, speeds, lat, gap, lanes, cdf, lane, s_fix, fixed,
                 min_ego_dist, mix_cdf, mix_lo, mix_hi, default_height, k, cross_prob,
                 xy, yaw, hl, hw, pts, hdg, start, npts, ds, length, vmax, succ_ptr, succ,
                 lkind, turn):  # pragma: no cover - numba
    """Place up to ``count`` moving agents of one ``kind`` clear of the ``xy`` rows
    and of each other (the ego is the last row of ``xy``).

    Args:
        rng: the episode's generator (draws: see the module doc).
        body: ``(8,)`` length range, width range [m], acceleration, comfortable
            decel [m/s^2], headway [s], jam gap [m] (:data:`dstenv.sim.spawn.BODY`).
        speeds: ``(3, 3)`` per kind (car, cyclist, pedestrian) the base speed [m/s]
            and the range of its factor; ``kind`` picks the row.
        lat: lateral offset from the lane centre [m] (left +); gap: clearance ahead
            and behind [m] for the free-spot test.
        lanes, cdf: candidate lanes and the cumulative length weights (``lane < 0``);
            or ``lane >= 0`` with arc length ``s_fix`` (NaN: drawn) and ``fixed``
            lanes to follow.
        min_ego_dist: [m] (0: none) from the ego's position (last row of ``xy``).
        mix_cdf, mix_lo, mix_hi: vehicle class cumulative weights ``(C,)`` (empty:
            no classes) and the size ranges ``(C, 3)`` (length, width, height [m]).
        default_height: body height [m] when no class is drawn.
        k: route length; cross_prob: crossing probability of the route choice.
        xy, yaw, hl, hw: the rows placed so far; the rest: lane network arrays.

    Returns:
        ``n`` placed, and rows ``xy (count, 2)``, ``yaw``, ``v``, ``hl``, ``hw``,
        ``route (count, k)``, ``s``, ``idm (count, 5)``, ``height`` (first ``n`` valid).
    """
    n0 = xy.shape[0]
    a_xy = np.empty((n0 + count, 2))
    a_xy[:n0] = xy
    a_yaw = np.empty(n0 + count)
    a_yaw[:n0] = yaw
    a_hl = np.empty(n0 + count)
    a_hl[:n0] = hl
    a_hw = np.empty(n0 + count)
    a_hw[:n0] = hw
    o_v = np.empty(count)
    o_route = np.empty((count, k), np.int64)
    o_s = np.empty(count)
    o_idm = np.empty((count, 5))
    o_h = np.empty(count)
    ex, ey = xy[n0 - 1, 0], xy[n0 - 1, 1]
    n = n0
    for _ in range(count):
        ln_w = rng.uniform(body[0], body[1])
        wd_w = rng.uniform(body[2], body[3])
        amax, bcomf = body[4], body[5]
        height = default_height
        if mix_cdf.shape[0] > 0:
            cls = np.searchsorted(mix_cdf, rng.random(), side="right")
            u = rng.random(3)
            ln_w = mix_lo[cls, 0] + u[0] * (mix_hi[cls, 0] - mix_lo[cls, 0])
            wd_w = mix_lo[cls, 1] + u[1] * (mix_hi[cls, 1] - mix_lo[cls, 1])
            height = mix_lo[cls, 2] + u[2] * (mix_hi[cls, 2] - mix_lo[cls, 2])
            if cls >= 2:  # vans and trucks: gentler acceleration and braking
                amax, bcomf = amax * 0.7, bcomf * 0.8
        f0 = speeds[0, 0] * rng.uniform(speeds[0, 1], speeds[0, 2])
        f1 = speeds[1, 0] * rng.uniform(speeds[1, 1], speeds[1, 2])
        f2 = speeds[2, 0] * rng.uniform(speeds[2, 1], speeds[2, 2])
        v0 = f0 if kind == 0 else (f1 if kind == 1 else f2)
        for _ in range(TRIES):
            ln = lane
            if lane < 0:
                ln = lanes[np.searchsorted(cdf, rng.random(), side="right")]
            lo, hi = ln_w / 2 + 0.5, length[ln] - ln_w / 2 - 0.5
            if hi <= lo:
                continue
            pos = rng.uniform(lo, hi) if math.isnan(s_fix) else min(max(s_fix, lo), hi)
            x, y, h = lane_pose(pts, hdg, start, npts, ds, ln, pos)
            x, y = x - lat * math.sin(h), y + lat * math.cos(h)
            if min_ego_dist > 0 and math.hypot(x - ex, y - ey) < min_ego_dist:
                continue
            if not free_spot(a_xy, a_yaw, a_hl, a_hw, n, x, y, h, ln_w, wd_w, gap):
                continue
            i = n - n0
            o_route[i] = plan_route_nb(ln, fixed, k, rng, succ_ptr, succ, lkind, turn,
                                       cross_prob)
            o_v[i] = min(v0, vmax[ln]) * rng.uniform(0.3, 0.8)
            a_xy[n, 0], a_xy[n, 1], a_yaw[n] = x, y, h
            a_hl[n], a_hw[n] = ln_w / 2, wd_w / 2
            o_s[i] = pos
            o_idm[i, 0], o_idm[i, 1], o_idm[i, 2] = v0, amax, bcomf
            o_idm[i, 3], o_idm[i, 4] = body[6], body[7]
            o_h[i] = height
            n += 1
            break
    m = n - n0
    return (m, a_xy[n0:n].copy(), a_yaw[n0:n].copy(), o_v[:m].copy(), a_hl[n0:n].copy(),
            a_hw[n0:n].copy(), o_route[:m].copy(), o_s[:m].copy(), o_idm[:m].copy(),
            o_h[:m].copy())


@nb.njit(cache=True)
def near_any(q, pts, r, squared):  # pragma: no cover - numba
    """``(N,) bool``: some point of ``pts (P, 2)`` lies within ``r`` of ``q[i] (N, 2)``:
    ``hypot(dx, dy) < r``, or ``dx^2 + dy^2 < r`` when ``squared`` (``d = q - p``)."""
    out = np.zeros(q.shape[0], np.bool_)
    for i in range(q.shape[0]):
        for j in range(pts.shape[0]):
            dx, dy = q[i, 0] - pts[j, 0], q[i, 1] - pts[j, 1]
            d = dx * dx + dy * dy if squared else math.hypot(dx, dy)
            if d < r:
                out[i] = True
                break
    return out
