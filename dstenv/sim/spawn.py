"""Placing agents: parked cars, moving traffic, pedestrians, the ego and task traffic.

Agents are rows of the world's state table (:mod:`dstenv.sim.agenttable`), the ego last.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from dstenv.sim.agenttable import FIELDS, add_row, empty_table, insert_rows, no_park
from dstenv.sim.lanes import LaneKind, LaneNetwork, lane_pose, project_on_lane
from dstenv.sim.parking import CLASS_HI, CLASS_LO
from dstenv.sim.placement import free_spot, near_any, place_mobile, plan_route_nb
from dstenv.sim.types import AGENT_HEIGHT, AgentKind, WorldMap

__all__ = ["populate", "respawn", "pull_out", "plan_route", "nearest_lane", "BODY"]

#: kind -> (length range, width range, accel, comfortable decel, headway, jam gap)
BODY = {
    AgentKind.CAR: ((3.9, 4.9), (1.7, 1.95), 1.5, 2.5, 1.2, 2.0),
    AgentKind.CYCLIST: ((1.7, 1.9), (0.55, 0.7), 1.0, 2.0, 1.0, 1.5),
    AgentKind.PEDESTRIAN: ((0.45, 0.55), (0.45, 0.55), 0.8, 1.5, 0.6, 0.4),
}
#: size ranges of the vehicle classes: (C, 3) low and high length, width, height [m]
_CLASS_LO, _CLASS_HI = CLASS_LO, CLASS_HI
#: (key, count asked for) already warned about: a shortfall is said once per process
_SHORT_WARNED: set[tuple[str, int]] = set()


def _say_short(key: str, asked: int, placed: int) -> None:
    """Warn (once per ``key`` and count) that the map held fewer agents than asked for."""
    if placed >= asked or (key, asked) in _SHORT_WARNED:
        return
    _SHORT_WARNED.add((key, asked))
    warnings.warn(f"world: {key} = {asked} does not fit on this map ({placed} placed, "
                  f"no free spot found for the rest); lower {key} or enlarge the map "
                  "(world.map.blocks_x, blocks_y)", RuntimeWarning, stacklevel=3)


def plan_route(net: LaneNetwork, lane: int, rng: np.random.Generator, k: int,
               cross_prob: float = 0.0, fixed: tuple[int, ...] = ()) -> np.ndarray:
    """``(k,) int64`` route starting with ``lane`` (then ``fixed``), random successors after
    (:func:`dstenv.sim.placement.plan_route_nb`)."""
    return plan_route_nb(int(lane), np.asarray(fixed, np.int64).reshape(-1), int(k), rng,
                         net.succ_ptr, net.succ, net.kind, net.turn, float(cross_prob))


def nearest_lane(net: LaneNetwork, x: float, y: float, yaw: float,
                 max_dist: float = 6.0) -> tuple[int, float] | None:
    """Closest vehicle lane point heading within 60 deg of ``yaw``: ``(lane, s)`` or None."""
    idx = np.flatnonzero(np.abs(net.pts[:, 0] - x) < max_dist)  # cheap test first
    lane_of = np.searchsorted(net.start, idx, side="right") - 1  # lanes are stored in order
    ok = (net.kind[lane_of] <= LaneKind.CONNECTOR) & (np.cos(net.hdg[idx] - yaw) > 0.5)
    idx, lane_of = idx[ok], lane_of[ok]
    if len(idx) == 0:
        return None
    d = np.hypot(net.pts[idx, 0] - x, net.pts[idx, 1] - y)
    k = int(np.argmin(d))
    if d[k] > max_dist:
        return None
    p = int(idx[k])
    lane = int(lane_of[k])
    return lane, float((p - net.start[lane]) * net.ds[lane])


def _add_parked(st: dict[str, np.ndarray], slots: np.ndarray, rng: np.random.Generator) -> None:
    """Append parked vehicles at ``slots`` ``(S, 6)`` (x, y, yaw, length, width, height;
    a slot of length 0 gets a car size drawn here) in one go."""
    n, k = len(slots), st["route"].shape[1]
    (l_lo, l_hi), (w_lo, w_hi) = BODY[AgentKind.CAR][:2]
    sized = slots[:, 3] > 0 if slots.shape[1] > 3 else np.zeros(n, bool)
    if sized.all():
        sizes = slots[:, 3:5] / 2
    else:
        sizes = np.stack([rng.uniform(l_lo, l_hi, n), rng.uniform(w_lo, w_hi, n)], -1) / 2
        if sized.any():
            sizes[sized] = slots[sized, 3:5] / 2
    height = np.where(sized, slots[:, 5], AGENT_HEIGHT[AgentKind.CAR]) if n else np.zeros(0)
    rows = {"xy": slots[:, :2], "yaw": slots[:, 2], "v": np.zeros(n), "hl": sizes[:, 0],
            "hw": sizes[:, 1], "akind": np.full(n, AgentKind.CAR, np.uint8),
            "mobile": np.zeros(n, bool), "parked": np.ones(n, bool),
            "route": np.full((n, k), -1, np.int64), "s": np.zeros(n), "lat": np.zeros(n),
            "grant": np.full(n, -1, np.int64), "req_t": np.full(n, np.inf),
            "stop_clock": np.zeros(n), "halt": np.zeros(n), "stuck": np.zeros(n, bool),
            "still": np.zeros(n), "lat_goal": np.zeros(n), "lc": np.zeros(n),
            "hazard": np.zeros(n, bool), "park": no_park(n), "idm": np.zeros((n, 5)),
            "height": height}
    for f in FIELDS:
        st[f] = np.concatenate([st[f], rows[f].astype(st[f].dtype)])


def _free(st, xy, yaw, length, width, gap) -> bool:
    """No body of ``st`` overlaps the box at ``xy``, ``yaw`` of ``length + 2 gap`` by
    ``width + 0.4`` [m] (:func:`dstenv.sim.placement.free_spot`)."""
    return bool(free_spot(st["xy"], st["yaw"], st["hl"], st["hw"], len(st["v"]), float(xy[0]),
                          float(xy[1]), float(yaw), float(length), float(width), float(gap)))


def _mobile(world_map, st, rng, cfg, kind, lanes, cdf, k, *, lane=None, s=None, fixed=(),
            at=None, min_ego_dist=0.0, count=1) -> int:
    """Place ``count`` moving agents, each on a random (or the given) lane, clear of
    the others (inserted before row ``at``, default: appended). Returns how many
    were placed (each gets :data:`~dstenv.sim.placement.TRIES` tries)."""
    net, tr = world_map.lanes, cfg["traffic"]
    (l_lo, l_hi), (w_lo, w_hi), amax, bcomf, headway, jam = BODY[kind]
    mix = tr["vehicle_mix"] if kind == AgentKind.CAR else []
    if len(mix):
        p = np.asarray(mix, np.float64)
        p = p / p.sum()
        mix_cdf = p.cumsum()  # as rng.choice(p=p) builds it
        mix_cdf /= mix_cdf[-1]
    else:
        mix_cdf = np.zeros(0)
    lat = -(net.lane_width / 2 - 0.8) if kind == AgentKind.CYCLIST else 0.0
    speeds = np.array([[tr["speed_limit"], 0.8, 1.2], [tr["cyclist_speed"], 0.8, 1.2],
                       [tr["pedestrian_speed"], 0.75, 1.25]], np.float64)
    placed = place_mobile(
        rng, int(count), int(kind), np.array([l_lo, l_hi, w_lo, w_hi, amax, bcomf, headway, jam],
                                             np.float64),
        speeds, float(lat), 0.3 if kind == AgentKind.PEDESTRIAN else 3.0,
        np.zeros(0, np.int64) if lanes is None else np.asarray(lanes, np.int64),
        np.zeros(0) if cdf is None else np.asarray(cdf, np.float64),
        -1 if lane is None else int(lane), np.nan if s is None else float(s),
        np.asarray(fixed, np.int64).reshape(-1), float(min_ego_dist), mix_cdf, _CLASS_LO,
        _CLASS_HI, float(AGENT_HEIGHT[int(kind)]), int(k), float(tr["crossing_prob"]),
        st["xy"], st["yaw"], st["hl"], st["hw"], net.pts, net.hdg, net.start, net.npts, net.ds,
        net.length, net.vmax, net.succ_ptr, net.succ, net.kind, net.turn)
    m, xy, yaw, v, hl, hw, route, s_arc, idm, height = placed
    if m:
        lat_a = np.full(m, lat)
        insert_rows(st, {"xy": xy, "yaw": yaw, "v": v, "hl": hl, "hw": hw,
                     "akind": np.full(m, int(kind), np.uint8), "mobile": np.ones(m, bool),
                     "parked": np.zeros(m, bool), "route": route, "s": s_arc, "lat": lat_a,
                     "grant": np.full(m, -1, np.int64), "req_t": np.full(m, np.inf),
                     "stop_clock": np.zeros(m), "halt": np.zeros(m), "stuck": np.zeros(m, bool),
                     "still": np.zeros(m), "lat_goal": lat_a.copy(), "lc": np.zeros(m),
                     "hazard": np.zeros(m, bool), "park": no_park(m), "idm": idm,
                     "height": height},
                len(st["v"]) if at is None else at)
    return int(m)


def populate(world_map: WorldMap, cfg: dict[str, Any], rng: np.random.Generator,
             k: int) -> dict[str, np.ndarray]:
    """All agents of a new episode: parked cars, ego, task traffic, moving traffic."""
    net, tr, ego = world_map.lanes, cfg["traffic"], cfg["ego"]
    st = empty_table(k)
    slots = world_map.meta.get("parking_slots", np.zeros((0, 6)))
    taken = rng.random(len(slots)) < tr["parked_density"]
    double = np.zeros(len(slots), bool)
    if tr["double_park_prob"] > 0:
        double = taken & (rng.random(len(slots)) < tr["double_park_prob"])
    _add_parked(st, slots[taken & ~double], rng)
    for slot in slots[double]:
        if _double_park(world_map, st, slot, cfg, rng, k) is None:
            _add_parked(st, slot[None], rng)  # no lane beside it: it parks after all
    lots = world_map.meta.get("lot_slots")
    if lots is not None and len(lots):  # every lot slot holds a car (sized: no draw)
        _add_parked(st, lots, rng)
    road = np.flatnonzero((net.kind == LaneKind.ROAD) & (net.length > 12.0))
    if len(road) == 0:
        road = np.flatnonzero(net.kind == LaneKind.ROAD)
    if len(road) == 0:
        raise ValueError("the map has no road lanes to place the ego on")
    ego_idm = (ego["autopilot_speed"], 1.5, 2.5, 1.2, 2.0)
    for _ in range(50):
        lane = int(rng.choice(road, p=net.length[road] / net.length[road].sum()))
        s = rng.uniform(0.25, 0.6) * net.length[lane]
        x, y, h = lane_pose(net.pts, net.hdg, net.start, net.npts, net.ds, lane, s)
        if _free(st, (x, y), h, ego["length"], ego["width"], 1.0):
            break
    add_row(st, AgentKind.CAR, (x, y), h, ego["length"], ego["width"], speed=ego["initial_speed"],
            route=plan_route(net, lane, rng, k), s=s, idm=ego_idm)
    st["mobile"][-1] = False  # moved by the bicycle model, not by the traffic step
    _task(world_map, st, rng, cfg, k, slots, taken)
    for kind, key, kinds in ((AgentKind.CAR, "cars", (LaneKind.ROAD,)),
                             (AgentKind.CYCLIST, "cyclists", (LaneKind.ROAD,)),
                             (AgentKind.PEDESTRIAN, "pedestrians", (LaneKind.SIDEWALK,))):
        count = int(tr[key])
        lanes = np.flatnonzero(np.isin(net.kind, kinds) & (net.length > 6.0))
        if kind == AgentKind.CYCLIST:
            lanes = lanes[net.rightmost[lanes]]
        if count == 0:
            continue
        placed = 0
        if len(lanes):
            w = net.length[lanes] / net.length[lanes].sum()
            cdf = w.cumsum()
            cdf /= cdf[-1]
            placed = _mobile(world_map, st, rng, cfg, kind, lanes, cdf, k, at=len(st["v"]) - 1,
                             count=count)
        _say_short(f"traffic.{key}", count, placed)
    return st


def _double_park(world_map: WorldMap, st: dict[str, np.ndarray], slot: np.ndarray,
                 cfg: dict[str, Any], rng: np.random.Generator, k: int) -> int | None:
    """A vehicle meant for parking ``slot`` ``(6,)`` stands in the kerb-side travel lane
    beside it instead: hazards on, halted for a drawn dwell time (exponential, mean
    ``traffic.double_park_duration``, at most 4x), then it drives off with the traffic.
    Its right side keeps 0.2 m from the lane edge. Returns its row, or None when no
    kerb lane runs beside the slot or the spot is not free."""
    net, tr = world_map.lanes, cfg["traffic"]
    x, y, yaw = slot[:3]
    found = nearest_lane(net, x, y, yaw, max_dist=net.lane_width + 2.5)
    if found is None or net.kind[found[0]] != LaneKind.ROAD or not net.rightmost[found[0]]:
        return None
    lane, s = found
    s, _, _ = project_on_lane(net.pts, net.start, net.npts, net.ds, lane, x, y, s, 3.0)
    if slot[3] > 0:
        length, width, height = (float(q) for q in slot[3:6])
    else:
        (l_lo, l_hi), (w_lo, w_hi) = BODY[AgentKind.CAR][:2]
        length, width, height = rng.uniform(l_lo, l_hi), rng.uniform(w_lo, w_hi), None
    if not length / 2 + 1.0 <= s <= net.length[lane] - length / 2 - 6.0:
        return None  # not on the stop line
    lat = -(net.lane_width / 2 - width / 2 - 0.2)
    lx, ly, h = lane_pose(net.pts, net.hdg, net.start, net.npts, net.ds, lane, s)
    cx, cy = lx - lat * np.sin(h), ly + lat * np.cos(h)
    if not _free(st, (cx, cy), h, length, width, 0.3):
        return None
    _, _, amax, bcomf, headway, jam = BODY[AgentKind.CAR]
    if length > 4.9:  # vans and trucks: gentler, as in traffic
        amax, bcomf = amax * 0.7, bcomf * 0.8
    v0 = tr["speed_limit"] * rng.uniform(0.8, 1.2)
    i = add_row(st, AgentKind.CAR, (cx, cy), h, length, width, route=plan_route(net, lane, rng, k),
                s=s, lat=lat, idm=(v0, amax, bcomf, headway, jam), height=height)
    mean = tr["double_park_duration"]
    st["halt"][i] = min(-mean * np.log(max(rng.random(), 1e-9)), 4.0 * mean)
    st["hazard"][i] = True
    st["lat_goal"][i] = 0.0  # when it drives off it moves over to the lane centre
    return i


def _task(world_map, st, rng, cfg, k, slots, taken) -> None:
    """Driving-task traffic: hidden cross traffic, parked cars and pedestrians by the route."""
    task, net = cfg["task"], world_map.lanes
    ego_route = st["route"][-1]
    route_lanes = [int(l) for l in ego_route if l >= 0]
    nodes = [int(net.node[l]) for l in route_lanes if net.kind[l] == LaneKind.CONNECTOR]
    placed = 0
    # lane owning each successor entry (CSR rows of succ_ptr), for vectorised look-ups
    owner = np.repeat(np.arange(len(net)), np.diff(net.succ_ptr))
    road_off_route = net.kind == LaneKind.ROAD
    road_off_route[route_lanes] = False
    for n in nodes:  # cars waiting to enter the ego's next junctions from side streets
        into = np.zeros(len(net), bool)
        into[owner[net.node[net.succ] == n]] = True  # a successor belongs to junction n
        approach = np.flatnonzero(into & road_off_route)
        for a in rng.permutation(approach) if len(approach) else []:
            if placed >= task["cross_traffic"]:
                break
            s = net.length[a] - rng.uniform(6.0, 30.0)
            if _mobile(world_map, st, rng, cfg, AgentKind.CAR, None, None, k, lane=int(a), s=s,
                       at=len(st["v"]) - 1):
                placed += 1
    pts = np.vstack([net.polyline(l) for l in route_lanes])
    if task["parked_near_route"] > 0 and len(slots):
        near = np.flatnonzero(near_any(slots[:, :2], pts, 6.0, False) & ~taken)
        for i in rng.permutation(near)[:task["parked_near_route"]]:
            x, y, yaw = slots[i, :3]
            if _free(st, (x, y), yaw, 4.5, 1.8, 0.3):
                add_row(st, AgentKind.CAR, (x, y), yaw, rng.uniform(3.9, 4.9),
                        rng.uniform(1.7, 1.95), parked=True, at=0)
    cross = np.flatnonzero(net.kind == LaneKind.CROSSING)
    first = net.pts[net.start[cross]]  # (C, 2) first point of each crossing
    near = near_any(first, pts, 15.0 ** 2, True)
    crossings = [int(c) for c in cross[near]] if len(cross) else []
    placed = 0
    for c in rng.permutation(crossings) if crossings else []:
        if placed >= task["crossing_pedestrians"]:
            break
        pred = owner[net.succ == c]  # ascending lane ids, like a scan over all lanes
        if len(pred):
            s = net.length[pred[0]] - rng.uniform(0.5, 4.0)
            if _mobile(world_map, st, rng, cfg, AgentKind.PEDESTRIAN, None, None, k,
                       lane=int(pred[0]), s=s, fixed=(int(c),), at=len(st["v"]) - 1):
                placed += 1


def pull_out(world_map: WorldMap, st: dict[str, np.ndarray], cfg: dict[str, Any],
             rng: np.random.Generator, k: int, min_ego_dist: float = 0.0) -> int | None:
    """A random parked car pulls out: it becomes a mobile agent on the nearest road lane
    heading its way, starting from its parking position (``lat`` = its offset from the
    lane centre, ``lat_goal`` = 0), so it moves sideways into the lane as it sets off.

    Args:
        min_ego_dist: [m] draw only among parked cars at least this far from the ego
            (0: any).

    Returns:
        The agent's row, or None when the drawn car has no lane next to it.
    """
    net, tr = world_map.lanes, cfg["traffic"]
    pick = st["parked"][:-1] & (st["akind"][:-1] == AgentKind.CAR)
    if min_ego_dist > 0:
        pick &= np.hypot(*(st["xy"][:-1] - st["xy"][-1]).T) >= min_ego_dist
    rows = np.flatnonzero(pick)
    if len(rows) == 0:
        return None
    i = int(rows[rng.integers(len(rows))])
    x, y = st["xy"][i]
    found = nearest_lane(net, x, y, st["yaw"][i], max_dist=5.5)
    if found is None or net.kind[found[0]] != LaneKind.ROAD:
        return None
    lane, s = found
    s, lat, _ = project_on_lane(net.pts, net.start, net.npts, net.ds, lane, x, y, s, 3.0)
    lx, ly, h = lane_pose(net.pts, net.hdg, net.start, net.npts, net.ds, lane, s)
    nx, ny = lx - lat * np.sin(h), ly + lat * np.cos(h)
    others = {f: np.delete(st[f], i, axis=0) for f in ("xy", "yaw", "hl", "hw", "v")}
    if not _free(others, (nx, ny), h, 2 * st["hl"][i], 2 * st["hw"][i] - 0.3, 0.05):
        return None  # turning to the lane heading would touch a neighbour: not now
    _, _, amax, bcomf, headway, jam = BODY[AgentKind.CAR]
    st["parked"][i], st["mobile"][i] = False, True
    st["route"][i] = plan_route(net, lane, rng, k)
    st["s"][i], st["lat"][i], st["lat_goal"][i], st["v"][i] = s, lat, 0.0, 0.0
    st["xy"][i] = nx, ny
    st["yaw"][i] = h
    st["idm"][i] = (tr["speed_limit"] * rng.uniform(0.8, 1.2), amax, bcomf, headway, jam)
    st["grant"][i], st["req_t"][i], st["halt"][i], st["still"][i] = -1, np.inf, 0.0, 0.0
    st["lc"][i], st["hazard"][i], st["park"][i] = 0.0, False, (-1.0, 0.0)
    return i


def respawn(world_map: WorldMap, st: dict[str, np.ndarray], i: int, rng: np.random.Generator,
            min_ego_dist: float = 60.0) -> None:
    """Move agent ``i`` (stuck at a dead end or in a gridlock) to a free lane of its
    kind far from the ego."""
    net = world_map.lanes
    walker = st["akind"][i] == AgentKind.PEDESTRIAN
    lanes = np.flatnonzero((net.kind == (LaneKind.SIDEWALK if walker else LaneKind.ROAD))
                           & (net.length > 8.0))
    if st["akind"][i] == AgentKind.CYCLIST and net.rightmost[lanes].any():
        lanes = lanes[net.rightmost[lanes]]
    k = st["route"].shape[1]
    keep = {f: st[f][i].copy() for f in ("hl", "hw", "akind", "idm")}
    # a respawned agent starts on its lane's usual line (cyclists keep to the kerb side)
    keep["lat"] = -(net.lane_width / 2 - 0.8) if keep["akind"] == AgentKind.CYCLIST else 0.0
    tmp = {f: np.delete(st[f], i, axis=0) for f in FIELDS}
    w = net.length[lanes] / net.length[lanes].sum()
    for _ in range(30):
        ln = int(rng.choice(lanes, p=w))
        lo = keep["hl"] + 0.5
        pos = rng.uniform(lo, max(net.length[ln] - lo, lo + 0.1))
        x, y, h = lane_pose(net.pts, net.hdg, net.start, net.npts, net.ds, ln, pos)
        if np.hypot(x - st["xy"][-1, 0], y - st["xy"][-1, 1]) < min_ego_dist:
            continue
        if _free(tmp, (x, y), h, 2 * keep["hl"], 2 * keep["hw"], 3.0):
            break
    st["route"][i] = plan_route(net, ln, rng, k)
    st["s"][i], st["v"][i], st["grant"][i], st["stuck"][i] = pos, 0.0, -1, False
    st["req_t"][i], st["stop_clock"][i], st["halt"][i], st["still"][i] = np.inf, 0.0, 0.0, 0.0
    st["lc"][i], st["hazard"][i], st["lat"][i], st["lat_goal"][i] = 0.0, False, keep["lat"], \
        keep["lat"]
    st["park"][i] = (-1.0, 0.0)
    st["xy"][i] = x - keep["lat"] * np.sin(h), y + keep["lat"] * np.cos(h)
    st["yaw"][i] = h
