"""Lane changes and overtaking (numba): which lane is beside which, and when to move over.

Called once per traffic step by :func:`dstenv.sim.traffic.traffic_step`, after car
following found each agent's leader (``blocker``, ``gap``, ``vlead``) and before
the agents move. Per vehicle row ``lc`` holds its manoeuvre:

* ``0``: none;
* ``-1``: moving sideways onto its (new) lane centre at lane-change speed (cleared
  when it gets there);
* ``> 0``: borrowing the oncoming lane of a one-lane-per-direction street to pass a
  standing vehicle, until its arc length ``s`` reaches ``lc`` [m].

Decisions:

1. **overtake**: a car (or cyclist) whose leader is a slow vehicle that is not itself
   queued (a halted delivery van, a double-parked car, a cyclist, a slow car with
   free road ahead) moves to the same-direction neighbour lane (left first, then
   right) if that lane is better there and the gaps on it are acceptable (a
   MOBIL-like safe-gap rule: the follower on the target lane need not brake hard,
   the leader there is not too close). The agent's route continues from the new lane
   (successors re-drawn).
2. **borrow**: with no same-direction lane beside it, a vehicle stopped behind a
   *standing* vehicle that is not queued passes it on the oncoming lane if the
   oncoming lane is free for the whole manoeuvre (its length plus what oncoming
   traffic covers meanwhile) and the pass ends 8 m before the stop line; otherwise it
   queues. It returns to its lane once its own lane is clear beside it, or aborts
   (returns behind the stopped vehicle) when oncoming traffic shows up in front.
3. **discretionary**: a car changes to a random neighbour lane at
   ``traffic.lane_change_rate`` [1/s] when the gaps there are generous.

The lateral move itself (``lat`` to ``lat_goal`` at up to ``lane_width /
lane_change_time``, slower at low speed, braking towards the end, heading turned
along the move) is done by the motion step of the traffic module. No move is ever
allowed to overlap another body: the traffic step's safety net still applies.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from dstenv.sim.lanes import LaneKind, LaneNetwork, lane_pose, project_on_lane
from dstenv.sim.types import AgentKind

__all__ = ["lane_neighbours", "lane_changes", "LC_NONE", "LC_MOVING"]

LC_NONE, LC_MOVING = 0.0, -1.0  # ``lc`` codes (> 0: borrowing until s reaches lc)
LOOK = 40.0  # [m] a slow leader closer than this is worth overtaking
MIN_LEFT = 30.0  # [m] no lane change without reason with less lane than this ahead (half
#                   of it to overtake)
RETURN_BEFORE = 8.0  # [m] a pass on the oncoming lane ends this far before the stop line
PASS_SPEED = 5.0  # [m/s] assumed mean speed over a pass from standstill (conservative)
_CAR, _CYCLIST, _PED = int(AgentKind.CAR), int(AgentKind.CYCLIST), int(AgentKind.PEDESTRIAN)
_K_ROAD = int(LaneKind.ROAD)


def lane_neighbours(net: LaneNetwork) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Road lanes beside each road lane, found from the geometry (any street shape).

    A lane ``m`` is beside lane ``l`` when the middle of ``l`` projects onto ``m`` 1.5 to
    4.8 m to the side, away from ``m``'s ends, and the two run parallel there.

    Returns:
        ``left, right, oncoming``: ``(L,) int64`` lane ids (-1: none): the
        same-direction lane on the left / right and the opposite-direction lane on the
        left (the oncoming lane of the innermost lane of a two-way street).
    """
    return _neighbours(net.pts, net.hdg, net.start, net.npts, net.ds, net.length,
                       net.kind.astype(np.int64))


@nb.njit(cache=True)
def _neighbours(pts, hdg, start, npts, ds, length, kind):  # pragma: no cover - numba
    n = start.shape[0]
    left, right, opp = np.full(n, -1), np.full(n, -1), np.full(n, -1)
    bl, br, bo = np.full(n, 1e9), np.full(n, 1e9), np.full(n, 1e9)
    # bounding boxes: a lane whose box is over 4.8 m away has every point so (the
    # rounded differences are monotone), so the cheap reject below rejects it anyway
    box = np.empty((n, 4))
    for b in range(n):
        box[b, 0], box[b, 1], box[b, 2], box[b, 3] = np.inf, -np.inf, np.inf, -np.inf
        for p in range(start[b], start[b] + npts[b]):
            box[b, 0], box[b, 1] = min(box[b, 0], pts[p, 0]), max(box[b, 1], pts[p, 0])
            box[b, 2], box[b, 3] = min(box[b, 2], pts[p, 1]), max(box[b, 3], pts[p, 1])
    for a in range(n):
        if kind[a] != _K_ROAD or length[a] < 4.0:
            continue
        x, y, h = lane_pose(pts, hdg, start, npts, ds, a, 0.5 * length[a])
        ch, sh = np.cos(h), np.sin(h)
        for b in range(n):
            if b == a or kind[b] != _K_ROAD:
                continue
            ex = max(box[b, 0] - x, x - box[b, 1], 0.0)
            ey = max(box[b, 2] - y, y - box[b, 3], 0.0)
            if ex ** 2 + ey ** 2 > 4.8 * 4.8:
                continue
            # cheap reject: b's points all far from the middle of a
            p0 = start[b]
            best, bp = 1e18, -1
            for p in range(p0, p0 + npts[b]):
                d2 = (pts[p, 0] - x) ** 2 + (pts[p, 1] - y) ** 2
                if d2 < best:
                    best, bp = d2, p
            if best > 4.8 * 4.8 or bp - p0 < 2 or p0 + npts[b] - 1 - bp < 2:
                continue
            c = np.cos(hdg[bp] - h)
            if abs(c) < 0.95:
                continue
            side = -(pts[bp, 0] - x) * sh + (pts[bp, 1] - y) * ch  # left +
            d = abs(side)
            if d < 1.5:
                continue
            if c > 0 and side > 0 and d < bl[a]:
                left[a], bl[a] = b, d
            elif c > 0 and side < 0 and d < br[a]:
                right[a], br[a] = b, d
            elif c < 0 and side > 0 and d < bo[a]:
                opp[a], bo[a] = b, d
    for a in range(n):  # a lane with a same-direction lane on its left has no oncoming one
        if left[a] >= 0 and opp[a] >= 0 and bl[a] < bo[a]:
            opp[a] = -1
    return left, right, opp


@nb.njit(cache=True)
def _gaps_on_lane(i, tl, s_t, route, s, v, hl, length):  # pragma: no cover - numba
    """Nearest bodies ahead / behind arc length ``s_t`` of lane ``tl`` (on it or on a
    lane leading into it): ``(gap_ahead, v_ahead, gap_behind, v_behind)`` [m, m/s]."""
    ga, va, gb, vb = 1e9, 0.0, 1e9, 0.0
    for j in range(route.shape[0]):
        if j == i:
            continue
        r0 = route[j, 0]
        if r0 == tl:
            d = s[j] - s_t
        elif r0 >= 0 and route[j, 1] == tl:
            d = s[j] - length[r0] - s_t
        else:
            continue
        if d >= 0.0:
            g = d - hl[i] - hl[j]
            if g < ga:
                ga, va = g, v[j]
        else:
            g = -d - hl[i] - hl[j]
            if g < gb:
                gb, vb = g, v[j]
    return ga, va, gb, vb


@nb.njit(cache=True)
def _oncoming_free(i, ol, s_o, need, t_pass, route, s, v, hl, length):  # pragma: no cover
    """Whether lane ``ol`` (running against the agent) stays free over ``need`` [m]
    ahead of the agent (at ``s_o`` on ``ol``) for ``t_pass`` [s]."""
    for j in range(route.shape[0]):
        if j == i:
            continue
        r0, r1 = route[j, 0], route[j, 1]
        if r0 == ol:
            d = s_o - s[j]
        elif r0 >= 0 and r1 == ol:
            d = s_o + length[r0] - s[j]
        elif r0 >= 0 and r1 >= 0 and route[j, 2] == ol:
            d = s_o + length[r1] + length[r0] - s[j]
        else:
            continue
        if d < -(hl[i] + hl[j] + 1.0):
            continue  # already behind the agent
        if d - hl[i] - hl[j] < need + v[j] * t_pass + 5.0:
            return False
    return True


@nb.njit(cache=True)
def _own_lane_clear(i, ln, s_i, route, s, hl, lat, lc, margin):  # pragma: no cover - numba
    """Nothing on lane ``ln`` (and in it, not borrowing) within ``margin`` [m] of the
    agent's body at ``s_i``."""
    for j in range(route.shape[0]):
        if j == i or route[j, 0] != ln or lc[j] > 0.0:
            continue
        if abs(s[j] - s_i) < hl[i] + hl[j] + margin and lat[j] < 1.5:
            return False
    return True


@nb.njit(cache=True)
def lane_changes(net, nbr, st, idm, planner, gaps, leads, blocker, dt, u, lc_rate, lc_time,
                 lane_width):  # pragma: no cover - numba
    """Start, steer and end lane changes and passes (state arrays updated in place).

    Args:
        net: the lane-network tuple of :func:`dstenv.sim.traffic.traffic_step`.
        nbr: ``(left, right, oncoming)`` of :func:`lane_neighbours`.
        st: its state tuple; idm: ``(B, 5)``; planner: ``(B,) bool`` rows planned
            this step; gaps, leads, blocker: ``(B,)`` free distance [m], leader speed
            [m/s] and leader row (-1: none, -2: a stop line) from car following.
        dt: step [s]; u: ``(B, >= 6)`` uniforms (column 4: discretionary change,
            5: its side); lc_rate: [1/s]; lc_time: [s] per lane; lane_width: [m].

    A row that changed lanes gets ``route[i, 0]`` = its new lane and ``route[i, 1]
    = -2``: the caller re-draws its successors.
    """
    (pts, hdg, start, npts, ds, length, lkind, node, turn, group, vmax, succ_ptr, succ,
     conf_ptr, conf, node_control, node_phase) = net
    left, right, opp = nbr
    (xy, yaw, v, hl, hw, akind, mobile, parked, route, s, lat, grant, req_t, stop_clock,
     halt, stuck, still, lat_goal, lc, hazard, park) = st
    nb_rows = xy.shape[0]
    for i in range(nb_rows - 1):  # never the ego
        if not planner[i] or akind[i] == _PED:
            continue
        ln = route[i, 0]
        if lc[i] == LC_MOVING:
            if abs(lat[i] - lat_goal[i]) < 0.05:
                lc[i] = LC_NONE
            continue
        base = -(lane_width / 2 - 0.8) if akind[i] == _CYCLIST else 0.0
        if lc[i] > 0.0:  # passing on the oncoming lane
            j = blocker[i]
            head_on = j >= 0 and np.cos(yaw[j] - yaw[i]) < -0.5 and gaps[i] < 30.0
            if (s[i] >= lc[i] or head_on or lkind[ln] != _K_ROAD) and \
                    _own_lane_clear(i, ln, s[i], route, s, hl, lat, lc, 2.0):
                lat_goal[i], lc[i] = base, LC_MOVING
            elif s[i] >= length[ln] - 1.0:  # (cannot happen: the pass ends before the line)
                lat_goal[i], lc[i] = base, LC_MOVING
            continue
        if lkind[ln] != _K_ROAD or halt[i] > 0.0 or hazard[i] or park[i, 0] >= 0.0:
            continue  # (a car pulling into a space keeps its lane)
        j = blocker[i]
        v0 = min(idm[i, 0], vmax[ln])
        motive = 0
        if j >= 0 and j < nb_rows - 1 and akind[j] != _PED and gaps[i] < LOOK:
            free_ahead = (not planner[j]) or gaps[j] > 15.0 or halt[j] > 0.0
            if free_ahead and leads[i] < 0.7 * v0 and v[j] < 0.7 * v0:
                motive = 1
        if motive == 0 and akind[i] == _CAR and lc_rate > 0.0 and u[i, 4] < lc_rate * dt:
            motive = 2
        if motive == 0:
            continue
        done = False
        for side in range(2):
            if motive == 2:  # a random side
                tl = left[ln] if (u[i, 5] < 0.5) == (side == 0) else right[ln]
            else:
                tl = left[ln] if side == 0 else right[ln]
            if tl < 0:
                continue
            s_t, lat_t, dist = project_on_lane(pts, start, npts, ds, tl, xy[i, 0], xy[i, 1],
                                               s[i] * length[tl] / length[ln], 15.0)
            if dist > 6.0 or s_t < hl[i] + 1.0 or \
                    length[tl] - s_t < (MIN_LEFT if motive == 2 else 0.5 * MIN_LEFT):
                continue
            ga, va, gb, vb = _gaps_on_lane(i, tl, s_t, route, s, v, hl, length)
            need_a = 2.0 + 0.8 * v[i] + max(v[i] - va, 0.0) ** 2 / 5.0
            need_b = 3.0 + 1.0 * vb + max(vb - v[i], 0.0) ** 2 / 4.0
            if motive == 2:
                need_a, need_b = max(1.5 * need_a, 25.0), 1.5 * need_b
            elif not (ga > gaps[i] + 10.0 or va > leads[i] + 2.0):
                continue  # no better there
            if ga < need_a or gb < need_b:
                continue
            lat[i] = lat_t
            lc[i] = LC_MOVING
            grant[i], req_t[i], stop_clock[i] = -1, np.inf, 0.0
            s[i] = s_t
            route[i, 0], route[i, 1] = tl, -2
            done = True
            break
        if done or motive != 1 or left[ln] >= 0 or opp[ln] < 0:
            continue
        # one lane per direction: pass a standing vehicle on the oncoming lane
        if not (v[j] < 0.3 and leads[i] < 0.3 and (halt[j] > 0.0 or not mobile[j])
                and gaps[i] < 25.0):
            continue
        s_end = s[i] + 2.0 * hl[i] + gaps[i] + 2.0 * hl[j] + 4.0
        if s_end > length[ln] - RETURN_BEFORE:
            continue
        ol = opp[ln]
        cx, cy, _ = lane_pose(pts, hdg, start, npts, ds, ln, s[i])
        s_o, _, w = project_on_lane(pts, start, npts, ds, ol, cx, cy,
                                    length[ol] - s[i] * length[ol] / length[ln], 15.0)
        if w > 4.8:
            continue
        need = s_end - s[i]
        t_pass = 2.0 * lc_time + need / PASS_SPEED
        if not _oncoming_free(i, ol, s_o, need, t_pass, route, s, v, hl, length):
            continue
        lat_goal[i] = base + w
        lc[i] = s_end
