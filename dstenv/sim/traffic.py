"""Vectorised traffic step (numba): junction right of way, IDM car following, lane motion.

Every mobile agent sits at arc length ``s`` on ``route[i, 0]`` and has its next
lanes planned in ``route[i, 1:]``. One step:

1. notes which connectors are held (occupied, or reserved by a grant);
2. the front agent of each lane requests the next controlled connector; requests are
   granted oldest first if the junction's rule allows (green light / full stop at
   a stop sign), no granted or older waiting connector conflicts and the exit lane
   has room (vehicles from one lane may follow each other through); steps 1-2 are
   :func:`dstenv.sim.routing.grant_connectors`;
3. each agent looks along its route for the nearest body (agent or ego) inside
   its corridor, an ungranted stop line or a blocked crosswalk, and takes the
   IDM acceleration towards it (of two standing agents that block each other,
   the lower row heeds only its next obstacle);
4. vehicles start, steer or end lane changes and passes on the oncoming lane
   (:mod:`dstenv.sim.lanechange`);
5. agents move along their lanes (and sideways towards their lateral goal); the
   travel is also clamped to the gap, so no agent ever drives into a body ahead of it;
6. a move (along or across the lane) that would still make two footprints overlap
   is undone. An agent
   standing for a minute (a gridlock from odd OSM junctions) out of the ego's
   sight is flagged ``stuck`` and replaced by the world.

The ego is the last row of the state arrays: it is an obstacle for everyone and,
under autopilot, it gets an acceleration from the same rules (its motion is
integrated by the bicycle model in :mod:`dstenv.sim.ego`).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from dstenv.sim.ego import box_overlap
from dstenv.sim.lanechange import LC_MOVING, LC_NONE, lane_changes
from dstenv.sim.lanes import lane_pose
from dstenv.sim.routing import (C_NONE, CAR, K_CONN, K_CROSS, K_ROAD, K_WALK,
                                PEDESTRIAN, choose_successor, grant_connectors)

__all__ = ["traffic_step", "n_randoms"]

PATH_MAX = 200  # points in an agent's look-ahead path
GRIDLOCK_TIME = 60.0  # [s] standstill (not a planned halt) after which an agent is ...
REPLACE_DIST = 90.0  # [m] ... replaced, if it is at least this far from the ego (unseen)
LC_YAW = 0.2  # [-] sideways speed / speed (at least 2.5 m/s) while changing lanes: the
#               heading turns at most ~0.2 rad off the lane
LC_LAT_ACCEL = 0.8  # [m/s^2] lateral deceleration at the end of a lane change
PARK_DECEL = 1.2  # [m/s^2] braking of a car pulling into a space (it stops at the target)


def n_randoms(n_route: int) -> int:
    """Columns of the uniform randoms ``u`` that :func:`traffic_step` takes per row."""
    return 5 + n_route


@nb.njit(cache=True)
def _seg_dist(px, py, ax, ay, bx, by):
    dx, dy = bx - ax, by - ay
    l2 = dx * dx + dy * dy
    t = 0.0 if l2 == 0 else min(max(((px - ax) * dx + (py - ay) * dy) / l2, 0.0), 1.0)
    return np.hypot(ax + t * dx - px, ay + t * dy - py)


@nb.njit(cache=True)
def traffic_step(net, nbr, trig, st, idm, rules, t, dt, u, ego_auto):
    """Advance all mobile agents by ``dt`` (state arrays are updated in place).

    Args:
        net: lane-network arrays ``(pts, hdg, start, npts, ds, length, kind, node,
            turn, group, vmax, succ_ptr, succ, conf_ptr, conf, node_control, node_phase)``.
        nbr: ``(left, right, oncoming)`` lanes beside each lane
            (:func:`dstenv.sim.lanechange.lane_neighbours`).
        trig: ``(cos, sin)`` of ``hdg`` (:attr:`dstenv.sim.lanes.LaneNetwork.heading_trig`).
        st: state arrays over B rows (ego last) ``(xy, yaw, v, hl, hw, akind, mobile,
            parked, route, s, lat, grant, req_t, stop_clock, halt, stuck, still,
            lat_goal, lc, hazard, park)`` (``lc``: lane-change state of
            :mod:`dstenv.sim.lanechange`; ``hazard``: double parked, hazard lights on,
            cleared when its halt ends; ``park (B, 2)``: a car pulling into a space,
            target arc length on its lane and lateral offset [m], ``park[:, 0] < 0``:
            none).
        idm: ``(B, 5)`` desired speed, max accel, comfortable decel, headway, jam gap.
        rules: ``(signal_green, stop_duration, halt_rate, halt_mean, pause_rate,
            pause_mean, crossing_prob, drift, drift_time, lateral_speed,
            delivery_factor, lane_change_rate, lane_change_time, lane_width)``.
        t: time [s]; dt: step [s]; u: ``(B, n_randoms(K))`` uniform randoms (0: route
            choice, 1-2: halts, 3: drift, 4-5: lane changes, 6..: successors after a
            lane change); ego_auto: plan the ego.

    Lateral motion of vehicles: ``lat`` follows ``lat_goal`` at up to
    ``lateral_speed`` [m/s] (a car pulling out of a parking space), and while a
    vehicle drives faster than 1 m/s it drifts around the goal (Ornstein-Uhlenbeck,
    std ``drift`` [m], correlation time ``drift_time`` [s], at most 2 std). During a
    lane change or pass it moves at up to ``1.2 lane_width / lane_change_time``
    (``LC_YAW * max(v, 2.5)`` at low speed, braking at ``LC_LAT_ACCEL`` towards the
    end), its heading turned along the move.

    A car pulling into a space (``park[i, 0] >= 0``, set by :mod:`dstenv.sim.pullin`)
    stops with its centre at the target arc length: never faster than the braking
    curve of ``PARK_DECEL``, and once on it (or past it) at the constant deceleration
    that stops it there (a leader beyond the target is left to the gap clamp). It
    neither halts, drifts nor changes lanes; once its whole body is beside the space
    and the run-in behind it (``2 hl + 0.3`` m before the target) it slides sideways
    to the target offset at up to ``lateral_speed`` (heading along the move); a
    sideways step that would touch a body (a cyclist beside it) is dropped and it
    rolls on in the lane. It is a body in its lane for everyone behind until it is
    out of it.

    Returns:
        ``(accel, gap, pulling)``: of the ego under autopilot the IDM acceleration
        [m/s^2] and the free distance ahead of it [m] (1e9 when nothing is in the
        way); the number of cars pulling into a space.
    """
    (pts, hdg, start, npts, ds, length, lkind, node, turn, group, vmax, succ_ptr, succ,
     conf_ptr, conf, node_control, node_phase) = net
    (xy, yaw, v, hl, hw, akind, mobile, parked, route, s, lat, grant, req_t, stop_clock,
     halt, stuck, still, lat_goal, lc, hazard, park) = st
    (green, stop_dur, halt_rate, halt_mean, pause_rate, pause_mean, cross_prob, drift,
     drift_time, lat_speed, delivery, lc_rate, lc_time, lane_width) = rules
    cos_h, sin_h = trig
    nb_rows = xy.shape[0]
    ego = nb_rows - 1
    n_route = route.shape[1]
    planner = mobile.copy()
    planner[ego] = ego_auto and route[ego, 0] >= 0
    grant_connectors(planner, route, s, v, hl, akind, grant, req_t, stop_clock, lkind, length,
                     node, group, succ_ptr, succ, conf_ptr, conf, node_control, node_phase, t,
                     dt, green, stop_dur)

    # 3. car following along the route
    acc = np.zeros(nb_rows)
    gaps, leads, gaps2, leads2 = np.full(nb_rows, 1e9), np.zeros(nb_rows), \
        np.full(nb_rows, 1e9), np.zeros(nb_rows)
    blocker = np.full(nb_rows, -1)
    vlims = np.zeros(nb_rows)
    path = np.empty((PATH_MAX, 6))  # x, y, heading, distance ahead, cos, sin of heading
    px, py = xy[:, 0].copy(), xy[:, 1].copy()  # contiguous: the reach test vectorises
    cands = np.empty(nb_rows, np.int64)
    for i in range(nb_rows):
        if not planner[i]:
            continue
        v0, amax, bcomf, headway, jam = idm[i, 0], idm[i, 1], idm[i, 2], idm[i, 3], idm[i, 4]
        ped = akind[i] == PEDESTRIAN
        look = min(max(v[i] * headway + v[i] * v[i] / (2 * bcomf) + jam + 2 * hl[i] + 4.0,
                       4.0 if ped else 15.0), 60.0)
        # look-ahead path and the special lanes on it
        npath = 0
        base = -s[i]
        vlim = min(v0, vmax[route[i, 0]])
        gap, vlead, blk, gap2, vlead2 = 1e9, 0.0, -1, 1e9, 0.0
        for k in range(n_route):
            ln = route[i, k]
            if ln < 0 or base > look:
                break
            if k > 0:
                if vmax[ln] < vlim:
                    vlim = min(vlim, np.sqrt(vmax[ln] ** 2 + 3.0 * max(base - hl[i], 0.0)))
                stop_here = False
                if lkind[ln] == K_CONN and node_control[node[ln]] != C_NONE and grant[i] != ln:
                    stop_here = True
                elif lkind[ln] == K_CROSS and base < 2.5:
                    a0, a1 = start[ln], start[ln] + npts[ln] - 1
                    for q in range(nb_rows):
                        if (akind[q] != PEDESTRIAN and not parked[q] and q != i
                                and _seg_dist(xy[q, 0], xy[q, 1], pts[a0, 0], pts[a0, 1],
                                              pts[a1, 0], pts[a1, 1]) < hl[q] + 2.0 + 2.5 * v[q]):
                            stop_here = True
                if stop_here:
                    gap, vlead, blk = base - hl[i] - 0.3, 0.0, -2
                    break
            i0 = 0 if k > 0 else int(np.floor(s[i] / ds[ln])) + 1
            for p in range(start[ln] + i0, start[ln] + npts[ln]):
                d = base + (p - start[ln]) * ds[ln]
                if npath >= PATH_MAX or d > look:
                    break
                h = hdg[p]
                ch, sh = cos_h[p], sin_h[p]
                path[npath, 0] = pts[p, 0] - lat[i] * sh
                path[npath, 1] = pts[p, 1] + lat[i] * ch
                path[npath, 2] = h
                path[npath, 3] = d
                path[npath, 4] = ch
                path[npath, 5] = sh
                npath += 1
            base += length[ln]
        reach = look + hl[i] + 8.0
        margin = 0.15 if ped else 0.3
        # bounding box of the path points: a body further from it than the largest
        # reach of the test below (0.3 m along, half widths plus margin across) cannot
        # meet the path, so the per-point test is skipped (the result is the same)
        bx0 = by0 = 1e18
        bx1 = by1 = -1e18
        for p in range(npath):
            bx0, bx1 = min(bx0, path[p, 0]), max(bx1, path[p, 0])
            by0, by1 = min(by0, path[p, 1]), max(by1, path[p, 1])
        # the rows within reach first, in a branch-free loop that vectorises (as a
        # loop of tests it was most of the step: 172 -> 142 us, the same rows in order)
        xi0, yi0, r2 = xy[i, 0], xy[i, 1], reach * reach
        ncand = 0
        for j in range(nb_rows):
            dx, dy = px[j] - xi0, py[j] - yi0
            cands[ncand] = j
            ncand += (dx * dx + dy * dy <= r2) & (j != i)
        for jj in range(ncand):
            j = cands[jj]
            pad = 0.3 + hw[i] + hl[j] + hw[j] + margin + 1e-6
            if (xy[j, 0] < bx0 - pad or xy[j, 0] > bx1 + pad or xy[j, 1] < by0 - pad
                    or xy[j, 1] > by1 + pad):
                continue
            for p in range(npath):
                h, ch, sh = path[p, 2], path[p, 4], path[p, 5]
                ex, ey = xy[j, 0] - path[p, 0], xy[j, 1] - path[p, 1]
                lon = ex * ch + ey * sh
                if abs(lon) > 0.3:
                    continue
                ca, sa = abs(np.cos(yaw[j] - h)), abs(np.sin(yaw[j] - h))
                # the safety margin is kept from moving bodies ahead; a standing body, or
                # one level with the agent, blocks only if the path really meets it (so
                # two agents never wait for each other)
                side = margin if path[p, 3] >= hl[i] and v[j] > 0.1 else 0.0
                if abs(-ex * sh + ey * ch) < hw[i] + hl[j] * sa + hw[j] * ca + side:
                    g = path[p, 3] + lon - hl[i] - (hl[j] * ca + hw[j] * sa)
                    vl = max(v[j] * np.cos(yaw[j] - h), 0.0)
                    if g < gap:  # the old nearest (maybe a stop line) becomes second
                        gap2, vlead2 = gap, vlead
                        gap, vlead, blk = g, vl, j
                    elif g < gap2:
                        gap2, vlead2 = g, vl
                    break
        gaps[i], leads[i], blocker[i], gaps2[i], leads2[i] = gap, vlead, blk, gap2, vlead2
        vlims[i] = 0.0 if halt[i] > 0.0 else vlim
    # two standing agents waiting for each other (odd junction geometry): the lower
    # row goes first, heeding only its next obstacle (the safety net still applies)
    for i in range(nb_rows):
        j = blocker[i]
        if planner[i] and j > i and planner[j] and blocker[j] == i and v[i] < 0.1 \
                and v[j] < 0.1:
            gaps[i], leads[i] = gaps2[i], leads2[i]
    for i in range(nb_rows):
        if not planner[i]:
            continue
        v0, amax, bcomf, headway, jam = idm[i, 0], idm[i, 1], idm[i, 2], idm[i, 3], idm[i, 4]
        vl, park_d = vlims[i], -1.0
        if park[i, 0] >= 0.0:  # pulling into a space: never faster than the braking curve
            park_d = max(park[i, 0] - s[i], 0.0)
            vl = min(vl, np.sqrt(2.0 * PARK_DECEL * park_d))
        if vl < 0.05:
            a = -min(bcomf, v[i] / dt)
        else:
            a = amax * (1.0 - (v[i] / vl) ** 4)
        if gaps[i] < 1e8 and not (park_d >= 0.0 and gaps[i] > park_d):
            dyn = v[i] * headway + v[i] * (v[i] - leads[i]) / (2 * np.sqrt(amax * bcomf))
            a -= amax * ((jam + max(0.0, dyn)) / max(gaps[i], 0.01)) ** 2
        if park_d >= 0.0 and v[i] * v[i] >= 2.0 * PARK_DECEL * park_d:
            a = min(a, -v[i] * v[i] / (2.0 * max(park_d, 1e-6)))  # stops at the target
        acc[i] = min(max(a, -3.0 if akind[i] == PEDESTRIAN else -9.0), amax)
    # 4. lane changes and passes; a vehicle that changed lanes re-draws its route
    lane_changes(net, nbr, st, idm, planner, gaps, leads, blocker, dt, u, lc_rate, lc_time,
                 lane_width)
    for i in range(nb_rows - 1):
        if route[i, 1] == -2:
            for k in range(1, n_route):
                prev = route[i, k - 1]
                route[i, k] = -1 if prev < 0 else choose_successor(
                    prev, u[i, 5 + k], succ_ptr, succ, lkind, turn, cross_prob)
    # 5. motion of the non-ego agents
    old_xy, old_yaw, old_s, old_route = xy.copy(), yaw.copy(), s.copy(), route.copy()
    old_lat = lat.copy()
    pulling = 0
    for i in range(nb_rows - 1):
        if not mobile[i]:
            continue
        if park[i, 0] >= 0.0:
            pulling += 1
        vn = max(v[i] + acc[i] * dt, 0.0)
        dist = 0.5 * (v[i] + vn) * dt
        if vn == 0.0 and acc[i] < 0.0:
            dist = min(v[i] * v[i] / (-2.0 * acc[i]), v[i] * dt)
        allowed = max(gaps[i] - 0.05, 0.0)
        if dist > allowed:
            dist = allowed
            vn = min(vn, dist / dt)
        if park[i, 0] >= 0.0 and dist >= park[i, 0] - s[i]:  # at the target: stop there
            dist, vn = max(park[i, 0] - s[i], 0.0), 0.0
        v[i] = vn
        s[i] += dist
        while s[i] > length[route[i, 0]]:
            if route[i, 1] < 0:
                s[i] = length[route[i, 0]]
                v[i] = 0.0
                stuck[i] = True
                break
            s[i] -= length[route[i, 0]]
            for k in range(n_route - 1):
                route[i, k] = route[i, k + 1]
            last = route[i, n_route - 2]
            route[i, n_route - 1] = -1 if last < 0 else choose_successor(
                last, u[i, 0], succ_ptr, succ, lkind, turn, cross_prob)
        dlat = 0.0
        if akind[i] != PEDESTRIAN:
            if park[i, 0] >= 0.0 and park[i, 0] - s[i] < 2.0 * hl[i] + 0.3:
                lat_goal[i] = park[i, 1]  # all of it is beside the space: move over
            off = lat[i] - lat_goal[i]
            if lc[i] != LC_NONE:  # changing lanes / passing: smooth sideways move
                vlat = min(1.2 * lane_width / lc_time, LC_YAW * max(v[i], 2.5),
                           np.sqrt(2.0 * LC_LAT_ACCEL * abs(off)) + 0.05)
                step = vlat * dt
                dlat = -min(max(off, -step), step)
                off = off + dlat
            elif park[i, 0] >= 0.0:  # pulling in: sideways, slowing down at the end
                step = min(lat_speed, np.sqrt(2.0 * LC_LAT_ACCEL * abs(off)) + 0.05) * dt
                dlat = -min(max(off, -step), step)
                off = off + dlat
            elif drift > 0.0 and v[i] > 1.0 and abs(off) < 2.0 * drift:
                a = dt / drift_time
                off = off * (1.0 - a) + drift * np.sqrt(2.0 * a) * (u[i, 3] - 0.5) * 3.4641016
                off = min(max(off, -2.0 * drift), 2.0 * drift)
            else:  # back to the goal (pulling out of a space, or out of a wide drift)
                step = lat_speed * dt
                off = off - min(max(off, -step), step)
            lat[i] = lat_goal[i] + off
        x, y, h = lane_pose(pts, hdg, start, npts, ds, route[i, 0], s[i])
        xy[i, 0], xy[i, 1], yaw[i] = x - lat[i] * np.sin(h), y + lat[i] * np.cos(h), h
        if dlat != 0.0:
            yaw[i] = h + np.arctan2(dlat / dt, max(v[i], 2.5))
        # a gridlock (rare, from odd junction geometry) is cleared out of the ego's sight
        still[i] = still[i] + dt if (v[i] < 0.1 and halt[i] <= 0.0) else 0.0
        if still[i] > GRIDLOCK_TIME:
            dx, dy = xy[i, 0] - xy[ego, 0], xy[i, 1] - xy[ego, 1]
            stuck[i] = dx * dx + dy * dy > REPLACE_DIST ** 2
        # halts of cars mid-block and pauses of pedestrians
        if halt[i] > 0.0:
            halt[i] -= dt
            if halt[i] <= 0.0 and hazard[i]:  # a double-parked vehicle drives off, moving
                hazard[i], lc[i] = False, LC_MOVING  # over to the lane centre as it goes
        elif akind[i] == PEDESTRIAN:
            if lkind[route[i, 0]] == K_WALK and u[i, 1] < pause_rate * dt:
                halt[i] = min(-pause_mean * np.log(max(u[i, 2], 1e-9)), 4.0 * pause_mean)
        elif akind[i] == CAR and lkind[route[i, 0]] == K_ROAD and park[i, 0] < 0.0 and \
                length[route[i, 0]] - s[i] > 25.0 and u[i, 1] < halt_rate * dt:
            # vans and trucks (longer than 4.9 m) halt like delivery vans: longer
            mean = halt_mean * (delivery if hl[i] > 2.45 else 1.0)
            halt[i] = min(-mean * np.log(max(u[i, 2], 1e-9)), 4.0 * mean)
    # 6. safety net: a move that would make two footprints overlap is undone (the agent
    # stands still for this step); earlier rows are final, later rows still old
    near = _near_index(xy, old_xy, hl, hw)
    for i in range(nb_rows - 1):
        if not mobile[i] or (old_s[i] == s[i] and old_route[i, 0] == route[i, 0]
                             and old_lat[i] == lat[i]):
            continue
        if not _touches(i, xy, yaw, hl, hw, old_xy, old_yaw, near):
            continue
        if park[i, 0] >= 0.0 and lat[i] != old_lat[i]:  # pulling in: roll on, not sideways
            lat[i] = old_lat[i]
            x, y, h = lane_pose(pts, hdg, start, npts, ds, route[i, 0], s[i])
            xy[i, 0], xy[i, 1], yaw[i] = x - lat[i] * np.sin(h), y + lat[i] * np.cos(h), h
            if not _touches(i, xy, yaw, hl, hw, old_xy, old_yaw, near):
                continue
        xy[i, 0], xy[i, 1], yaw[i], s[i], v[i] = \
            old_xy[i, 0], old_xy[i, 1], old_yaw[i], old_s[i], 0.0
        route[i, :] = old_route[i, :]
        lat[i] = old_lat[i]
    return acc[ego], gaps[ego], pulling


@nb.njit(cache=True)
def _near_index(xy, old_xy, hl, hw):
    """Rows sorted by their old x, for :func:`_touches`: ``(order, xs, pad)`` with
    ``pad`` the largest ``hl + hw`` plus the largest x move of this step [m]. Any
    pose of row ``j`` this step (old, new, or a move undone) is within that move of
    ``xs``, so two footprints that can overlap (centres closer than the sum of their
    ``hl + hw``, the first test of :func:`box_overlap`) have ``|xs[j] - x_i| <= hl_i +
    hw_i + pad``."""
    order = np.argsort(old_xy[:, 0], kind="mergesort")
    xs = old_xy[order, 0].copy()
    pad = 0.0
    for j in range(xy.shape[0]):
        pad = max(pad, abs(xy[j, 0] - old_xy[j, 0]))
    return order, xs, pad + np.max(hl + hw) + 1e-6


@nb.njit(cache=True)
def _touches(i, xy, yaw, hl, hw, old_xy, old_yaw, near):
    """Row ``i``'s footprint overlaps another (rows before ``i`` at their new, rows
    after it at their old pose); ``near``: :func:`_near_index` (only rows in its x window
    are tested: the same answer as testing all)."""
    order, xs, pad = near
    reach = hl[i] + hw[i] + pad
    lo = np.searchsorted(xs, xy[i, 0] - reach, side="left")
    hi = np.searchsorted(xs, xy[i, 0] + reach, side="right")
    for q in range(lo, hi):
        j = order[q]
        if j == i:
            continue
        jx, jy, jh = (xy[j, 0], xy[j, 1], yaw[j]) if j < i else \
            (old_xy[j, 0], old_xy[j, 1], old_yaw[j])
        if box_overlap(xy[i, 0], xy[i, 1], yaw[i], hl[i], hw[i], jx, jy, jh, hl[j], hw[j]):
            return True
    return False
