"""Routes and right of way (numba): successor choice, look-ups along a route, signal
phases and the connector grants of :func:`dstenv.sim.traffic.traffic_step`.

Grants, each step (:func:`grant_connectors`): junction connectors are held by the
agents on them and by granted reservations; the front agent of each lane asks for the
next controlled connector (looking through uncontrolled ones: bends, roundabout ring
pieces) once within its braking distance (+ 3 m); requests are granted oldest first,
those from inside a junction (circulating) before those entering it, if the junction's
rule allows (green light / full stop at a stop sign), no held or older waiting
connector conflicts and the exit lane has room.
"""

from __future__ import annotations

from typing import Any

import numba as nb
import numpy as np

from dstenv.sim.lanes import lane_pose

__all__ = ["choose_successor", "route_point", "signal_green", "grant_connectors",
           "CAR", "CYCLIST", "PEDESTRIAN", "K_ROAD", "K_CONN", "K_WALK", "K_CROSS",
           "C_NONE", "C_YIELD", "C_STOP", "C_SIGNAL", "ALL_RED", "AMBER",
           "gridlocked", "GRIDLOCK_SECONDS"]

CAR, CYCLIST, PEDESTRIAN = 0, 1, 2  # AgentKind codes (kept numeric for numba)
K_ROAD, K_CONN, K_WALK, K_CROSS = 0, 1, 2, 3  # LaneKind codes
C_NONE, C_YIELD, C_STOP, C_SIGNAL = 0, 1, 2, 3  # Control codes
ALL_RED = 3.0  # [s] clearance time between signal phases
AMBER = 3.0  # [s] end of a green phase in which no new vehicle is let in


@nb.njit(cache=True)
def choose_successor(lane, u, succ_ptr, succ, lkind, turn, cross_prob):
    """Random next lane after ``lane`` (-1 at a dead end); straight on is preferred."""
    a, b = succ_ptr[lane], succ_ptr[lane + 1]
    if a == b:
        return -1
    total = 0.0
    for k in range(a, b):
        total += _weight(succ[k], lkind, turn, cross_prob)
    x = u * total
    for k in range(a, b):
        x -= _weight(succ[k], lkind, turn, cross_prob)
        if x <= 0.0:
            return succ[k]
    return succ[b - 1]


@nb.njit(cache=True)
def _weight(c, lkind, turn, cross_prob):
    if lkind[c] == K_CONN:
        return 2.0 if turn[c] == 0 else (0.3 if turn[c] == 3 else 1.0)
    if lkind[c] == K_CROSS:
        return cross_prob
    if lkind[c] == K_WALK:
        return 1.0 - cross_prob
    return 1.0


@nb.njit(cache=True)
def route_point(route, s, d, pts, hdg, start, npts, ds, length):
    """World ``(x, y, yaw)`` at distance ``d`` [m] ahead of ``s`` along ``route``."""
    target = s + d
    k = 0
    while k < route.shape[0] - 1 and route[k + 1] >= 0 and target > length[route[k]]:
        target -= length[route[k]]
        k += 1
    return lane_pose(pts, hdg, start, npts, ds, route[k], min(target, length[route[k]]))


@nb.njit(cache=True)
def _green(group, t, phase, green):
    cycle = 2.0 * (green + ALL_RED)
    tt = (t + phase) % cycle
    open_for = max(green - AMBER, 1.0)
    if group == 0:
        return tt < open_for
    return cycle / 2 <= tt < cycle / 2 + open_for


def signal_green(group: int, t: float, phase: float, green: float) -> bool:
    """Whether signal group ``group`` (0/1) of a junction with offset ``phase`` [s]
    lets vehicles in at time ``t`` [s] (``green`` [s] per phase, amber and all-red
    included as in :func:`traffic_step`)."""
    return bool(_green(group, t, phase, green))


@nb.njit(cache=True)
def grant_connectors(planner, route, s, v, hl, akind, grant, req_t, stop_clock, lkind, length,
                     node, group, succ_ptr, succ, conf_ptr, conf, node_control, node_phase, t,
                     dt, green, stop_dur):
    """Right of way at junctions for one step (module docstring); ``grant``, ``req_t``
    and ``stop_clock`` (``(B,)``, ego last) are updated in place.

    Args:
        planner: ``(B,) bool`` rows that plan (mobile agents, the ego under autopilot).
        route, s, v, hl, akind: state arrays of :func:`dstenv.sim.traffic.traffic_step`.
        lkind ... node_phase: lane-network arrays (connector conflicts in CSR form).
        t: time [s]; dt: step [s]; green: [s] per signal phase; stop_dur: [s] full
            stop at a stop sign.
    """
    nb_rows = route.shape[0]
    n_route = route.shape[1]
    # 1. junctions are held by the agents on their connectors (occupancy, rows 0..B-1)
    # and by granted reservations of the next connector (rows B..2B-1); a reservation
    # turns into occupancy when the agent enters the connector
    held = np.full(2 * nb_rows, -1)
    for i in range(nb_rows):
        if grant[i] >= 0 and route[i, 0] == grant[i]:
            grant[i] = -1
        if route[i, 0] >= 0 and lkind[route[i, 0]] == K_CONN:
            held[i] = route[i, 0]
        held[nb_rows + i] = grant[i]
    # 2. requests by the front agent of each lane for the next controlled connector
    n_lanes = lkind.shape[0]
    front = np.full(n_lanes, -1)
    for i in range(nb_rows):
        if planner[i] and (front[route[i, 0]] < 0 or s[i] > s[front[route[i, 0]]]):
            front[route[i, 0]] = i
    req_c = np.full(nb_rows, -1)
    for i in range(nb_rows):
        asking = False
        if planner[i] and akind[i] != PEDESTRIAN and grant[i] < 0 and front[route[i, 0]] == i:
            d = length[route[i, 0]] - s[i] - hl[i]
            for k in range(1, n_route):
                ln = route[i, k]
                if ln < 0 or d > 60.0:
                    break
                if lkind[ln] == K_CONN and node_control[node[ln]] != C_NONE:
                    req_c[i] = ln
                    break
                # an uncontrolled connector (a bend, a roundabout's ring piece) is looked
                # through: its stop line is the next controlled one's, which the agent
                # may reach with its body still behind it
                if front[ln] >= 0:  # someone is ahead on the way: it asks first
                    break
                d += length[ln]
            if req_c[i] >= 0 and d < max(6.0, v[i] * v[i] / 6.0 + 3.0):  # braking dist + 3 m
                asking = True
                if v[i] < 0.1 and d < 3.0:
                    stop_clock[i] += dt
        if not asking:
            req_t[i] = np.inf
            stop_clock[i] = 0.0
        elif req_t[i] == np.inf:
            req_t[i] = t
    # oldest first; but a request from a connector (circulating in a roundabout, or
    # coming out of a bend) goes before those entering from a road: entering traffic
    # yields to the traffic already in the junction
    key = req_t.copy()
    for i in range(nb_rows):
        if req_c[i] >= 0 and key[i] < np.inf:
            for k in range(1, n_route):
                if route[i, k] == req_c[i]:
                    if lkind[route[i, k - 1]] == K_CONN:
                        key[i] -= 1e9
                    break
    order = np.argsort(key)
    # how many held / granted / waiting entries name each lane: a request conflicts
    # when any lane of its conflict list is named (one pass over that list)
    named = np.zeros(n_lanes, np.int64)
    for k in range(2 * nb_rows):
        if held[k] >= 0:
            named[held[k]] += 1
    for oi in range(nb_rows):
        i = order[oi]
        if req_t[i] == np.inf:
            break
        c = req_c[i]
        n = node[c]
        ok = True
        if node_control[n] == C_SIGNAL:
            ok = _green(group[c], t, node_phase[n], green)
        elif node_control[n] == C_STOP:
            ok = stop_clock[i] >= stop_dur
        if not ok:
            continue
        # no overtaking: a request never jumps an older conflicting one that waits
        for q in range(conf_ptr[c], conf_ptr[c + 1]):
            if named[conf[q]] > 0:
                ok = False
                break
        if not ok:  # conflicting traffic has the junction: later conflicting ones wait too
            named[c] += 1
            continue
        # the exit lane must have room (never block the box); a lane shorter than a
        # car only needs to be empty
        ex = succ[succ_ptr[c]]
        room = length[ex]
        for k in range(nb_rows):
            if route[k, 0] == ex:
                room = min(room, s[k] - hl[k])
            for g in (held[k], held[nb_rows + k]):
                if g >= 0 and succ[succ_ptr[g]] == ex:
                    room -= 2.0 * hl[k] + 3.0
        if room >= min(2.0 * hl[i] + 3.0, length[ex] - 0.01):
            grant[i] = c
            held[nb_rows + i] = c
            named[c] += 1
            req_t[i] = np.inf
            stop_clock[i] = 0.0


GRIDLOCK_SECONDS = 20.0  # [s] standstill outside a planned halt that counts as gridlock


def gridlocked(world: Any, steps: int) -> tuple[int, int]:
    """Step ``world`` (a :class:`dstenv.sim.World`) ``steps`` times and count
    vehicle-steps (mobile cars and cyclists): ``(stuck, total)``, stuck meaning
    standing still longer than :data:`GRIDLOCK_SECONDS` outside a planned halt (the
    right-of-way rules' health check: ``docs/gridlock.py``, ``tests/sim/test_traffic.py``).
    """
    total = stuck = 0
    for _ in range(steps):
        world.step()
        st = world._state
        vehicle = ~st["parked"][:-1] & (st["akind"][:-1] != PEDESTRIAN)
        total += int(vehicle.sum())
        stuck += int((vehicle & (st["still"][:-1] > GRIDLOCK_SECONDS)).sum())
    return stuck, total
