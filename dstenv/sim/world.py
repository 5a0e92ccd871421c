"""The 2-D urban world: a map, traffic agents and an ego vehicle, stepped at ``dt``."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from dstenv.config import section
from dstenv.sim import agenttable, pullin, spawn
from dstenv.sim.citygen import generate_city
from dstenv.sim.clutter import street_clutter
from dstenv.sim.ego import bicycle_step, hits, pure_pursuit, pursuit_lookahead
from dstenv.sim.lanes import Control, LaneKind, LaneNetwork, Turn, lane_pose, project_on_lane
from dstenv.sim.lanechange import lane_neighbours
from dstenv.sim.routing import choose_successor, route_point, signal_green
from dstenv.sim.shadow import ShadowAutopilot, autopilot_limit
from dstenv.sim.traffic import n_randoms, traffic_step
from dstenv.sim.types import AgentKind, Agents, WorldMap

__all__ = ["World"]

ROUTE_LEN = 8  # lanes planned ahead of every agent
_POOL_SALT = 0x4D4150  # seeds map k of a map pool: default_rng([k, _POOL_SALT])


class World:
    """A seeded urban traffic scene around a controllable ego vehicle.

    Args:
        config: overrides of :func:`dstenv.sim.default_config` (validated).
        seed: seed of the first episode (``reset`` is called once here).
        world_map: a ready map (hand-built or loaded) used instead of ``map.kind``;
            it needs a :class:`~dstenv.sim.lanes.LaneNetwork` in ``lanes``.
        base_dir: directory that resolves a relative ``map.osm_file`` (default: the
            current directory, then the shipped scenarios).

    All randomness comes from one ``np.random.Generator`` seeded by :meth:`reset`:
    the same seed gives bit-identical maps, agents and trajectories.

    Attributes:
        map: the episode's :class:`WorldMap` (a new city per reset for ``procedural``).
        agents: :class:`Agents` other than the ego (copies).
        agent_lanes: ``(N,) int64`` current lane of each agent (-1 parked).
        ego_pose: ``(3,)`` ``(x, y, yaw)``; ego_speed [m/s]; ego_steer [rad];
            ego_size ``(length, width)`` [m].
        time: [s] since reset; steps: steps since reset; seed: the episode seed.
        collision: the ego overlaps an agent or a building; off_road: part of the
            ego is off the road raster.
        route: ``(8,)`` lanes the ego follows (current first); route_progress: [m]
            driven along it since reset; lane_offset: [m] from its centre-line
            (left +); route_polyline(ahead, spacing): points ahead on the route.
        shadow: ``None`` or a :class:`~dstenv.sim.shadow.ShadowAutopilot`, asked each step.
    """

    def __init__(self, config: Mapping[str, Any] | None = None, seed: int | None = 0, *,
                 world_map: WorldMap | None = None, base_dir: str | Path | None = None) -> None:
        self.config = section("world", config)
        self._fixed_map = world_map
        self._base_dir = Path(base_dir) if base_dir is not None else None
        self._pool: dict[int, WorldMap] = {}  # map pool: index -> map (map.pool > 0)
        self._pool_nbr: dict[int, Any] = {}  # map pool: index -> its lane neighbours
        self.map_index = -1  # index of the episode's map in the pool (-1: no pool)
        self._map: WorldMap | None = None
        self.shadow: ShadowAutopilot | None = None
        if world_map is None and self.config["map"]["kind"] == "osm":
            self._fixed_map = self._load_osm()
        self.reset(seed)

    # ------------------------------------------------------------------ episode
    def reset(self, seed: int | None = None, keep_map: bool = False) -> None:
        """Start an episode from ``seed``: agents and ego, and the map.

        Args:
            seed: the episode seed (all randomness of the episode derives from it).
            keep_map: keep the current map (a fixed ``world_map`` or OSM map is always
                kept). Otherwise ``map.pool = 0`` generates a new city from ``seed``;
                ``map.pool = N > 0`` draws map ``k`` in ``0..N-1`` from ``seed`` and
                generates it once (from ``default_rng([k, salt])``, so map ``k`` is the
                same in every process), Procgen's ``num_levels``.
        """
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        pool = int(self.config["map"]["pool"])
        kept, self.map_index = getattr(self, "map_index", -1), -1
        if self._fixed_map is not None:
            self._map = self._fixed_map
            self._map.kerb_height = self.config["map"]["kerb_height"]
        elif keep_map and self._map is not None:
            self.map_index = kept  # a pool map stays the pool's map k
        elif pool > 0:
            k = int(self.rng.integers(pool))
            if k not in self._pool:
                self._pool[k] = generate_city(self.config["map"], self.config["traffic"],
                                              np.random.default_rng([k, _POOL_SALT]),
                                              self.config["clutter"])
            self._map = self._pool[k]
            self.map_index = k
        else:
            self._map = generate_city(self.config["map"], self.config["traffic"], self.rng,
                                      self.config["clutter"])
        if not isinstance(self._map.lanes, LaneNetwork):
            raise ValueError("world map has no lane network (WorldMap.lanes)")
        self.time = 0.0
        self.steps = 0
        self.route_progress = 0.0
        if getattr(self, "_nbr_of", None) is not self._map.lanes:  # once per lane network
            nbr = self._pool_nbr.get(self.map_index)  # (a pool map keeps its neighbours)
            self._nbr = lane_neighbours(self._map.lanes) if nbr is None else nbr
            self._net = agenttable.net_tuple(self._map.lanes)
            self._nbr_of = self._map.lanes
            if self.map_index >= 0:
                self._pool_nbr[self.map_index] = self._nbr
        self._state = spawn.populate(self._map, self.config, self.rng, ROUTE_LEN)
        self._steer = 0.0
        self._lane_offset = 0.0
        self._update_flags()
        self._ask_shadow(reset=True)

    def step(self, ego_action: tuple[float, float] | np.ndarray | None = None) -> None:
        """Advance the world by ``dt``.

        Args:
            ego_action: ``(acceleration [m/s^2], steering angle [rad])`` of the ego,
                clipped to ``ego.max_accel`` / ``ego.max_steer``; ``None`` drives the
                ego by autopilot (route following with the traffic's IDM rule).
        """
        cfg, ego_cfg, st = self.config, self.config["ego"], self._state
        dt, net = cfg["dt"], self._map.lanes
        auto = ego_action is None
        u = self.rng.random((len(st["v"]), n_randoms(ROUTE_LEN)))
        acc, gap, pulling = traffic_step(
            self._net, self._nbr, net.heading_trig, agenttable.state_tuple(st),
            st["idm"], agenttable.rules_tuple(cfg["traffic"], net.lane_width), self.time, dt,
            u, auto)
        e = len(st["v"]) - 1
        x, y, yaw, v = st["xy"][e, 0], st["xy"][e, 1], st["yaw"][e], st["v"][e]
        if auto:  # IDM, and never further than the free gap ahead (like the traffic agents)
            accel, steer = autopilot_limit(acc, gap, v, dt), self.route_steer()
        else:
            try:
                a = np.asarray(ego_action, np.float64).reshape(-1)
            except (TypeError, ValueError):  # a meta-action name: the highway world's
                a = np.full(1, np.nan)
            if a.shape != (2,) or not np.isfinite(a).all():
                raise ValueError(f"ego_action must be finite (accel, steer), got {ego_action!r}")
            accel = float(np.clip(a[0], -ego_cfg["max_accel"], ego_cfg["max_accel"]))
            steer = float(np.clip(a[1], -ego_cfg["max_steer"], ego_cfg["max_steer"]))
        nx, ny, nyaw, nv = bicycle_step(x, y, yaw, v, accel, steer, ego_cfg["wheelbase"], dt,
                                        ego_cfg["max_speed"])
        st["xy"][e], st["yaw"][e], st["v"][e] = (nx, ny), nyaw, nv
        self._steer = steer
        self._localise(u[e, 0])
        for i in np.flatnonzero(st["stuck"][:-1]):
            spawn.respawn(self._map, st, int(i), self.rng)
        rate = cfg["traffic"]["pull_out_rate"]
        if rate > 0:
            n = int(np.count_nonzero(st["parked"][:-1]))
            for _ in range(self.rng.poisson(rate * dt * n) if n else 0):
                spawn.pull_out(self._map, st, self.config, self.rng, ROUTE_LEN)
        rate = cfg["traffic"]["pull_in_rate"]
        if rate > 0:  # cars pulling into spaces (a parked one far away pulls out for each)
            if pulling:
                pullin.settle(self._map, st, self.config, self.rng, ROUTE_LEN)
            pullin.start_pull_ins(self._map, st, rate, dt, self.rng)
        self.time = round(self.time + dt, 9)
        self.steps += 1
        self._update_flags()
        self._ask_shadow()

    def add_agent(self, kind: AgentKind, lane: int, s: float, speed: float = 0.0,
                  route: tuple[int, ...] = ()) -> int:
        """Put a moving agent on ``lane`` at arc length ``s`` [m] (hand-built scenes).

        Args:
            kind: car, cyclist or pedestrian (vehicles need a road lane, pedestrians a
                sidewalk lane).
            lane: lane id in ``map.lanes``; s: [m]; speed: initial speed [m/s].
            route: lanes to follow after ``lane`` (random successors after them).

        Returns:
            The agent's index in :attr:`agents`.
        """
        net, tr = self._map.lanes, self.config["traffic"]
        if not 0 <= lane < len(net):
            raise ValueError(f"add_agent: no lane {lane} (the map has {len(net)})")
        walk = kind == AgentKind.PEDESTRIAN
        if (net.kind[lane] in (LaneKind.SIDEWALK, LaneKind.CROSSING)) != walk:
            raise ValueError(f"add_agent: a {AgentKind(kind).name.lower()} cannot use lane {lane} "
                             f"({LaneKind(net.kind[lane]).name.lower()})")
        (l_lo, l_hi), (w_lo, w_hi), amax, bcomf, headway, jam = spawn.BODY[AgentKind(kind)]
        v0 = {AgentKind.CAR: tr["speed_limit"], AgentKind.CYCLIST: tr["cyclist_speed"],
              AgentKind.PEDESTRIAN: tr["pedestrian_speed"]}[AgentKind(kind)]
        lat = -(net.lane_width / 2 - 0.8) if kind == AgentKind.CYCLIST else 0.0
        x, y, h = lane_pose(net.pts, net.hdg, net.start, net.npts, net.ds, lane, s)
        plan = spawn.plan_route(net, lane, self.rng, ROUTE_LEN, tr["crossing_prob"], tuple(route))
        st = self._state
        i = agenttable.add_row(st, kind, (x - lat * np.sin(h), y + lat * np.cos(h)), h,
                               (l_lo + l_hi) / 2, (w_lo + w_hi) / 2, speed=speed, route=plan,
                               s=s, lat=lat, idm=(v0, amax, bcomf, headway, jam),
                               at=len(st["v"]) - 1)
        self._update_flags()
        return i

    def place_ego(self, lane: int, s: float, speed: float = 0.0) -> None:
        """Move the ego onto ``lane`` at arc length ``s`` [m] with ``speed`` [m/s]."""
        net, st = self._map.lanes, self._state
        x, y, h = lane_pose(net.pts, net.hdg, net.start, net.npts, net.ds, lane, s)
        st["xy"][-1], st["yaw"][-1], st["v"][-1], st["s"][-1] = (x, y), h, speed, s
        st["route"][-1] = spawn.plan_route(net, lane, self.rng, ROUTE_LEN)
        st["grant"][-1] = -1
        self._update_flags()
        self._ask_shadow(reset=True)

    def set_turn(self, turn: Turn) -> bool:
        """Choose the ego's manoeuvre at its next junction (the rest of the route re-planned).

        Args:
            turn: :class:`dstenv.sim.lanes.Turn` (STRAIGHT, LEFT, RIGHT).

        Returns:
            True if the next junction offers that manoeuvre from the ego's lane and the
            route now takes it; False (route unchanged) if it does not, or if the ego is
            already inside the junction.
        """
        net, st = self._map.lanes, self._state
        route = st["route"][-1]
        if net.kind[route[0]] == LaneKind.CONNECTOR:
            return False  # too late: already inside the junction
        k = next((i for i in range(1, len(route))
                  if route[i] >= 0 and net.kind[route[i]] == LaneKind.CONNECTOR), None)
        if k is None:
            return False
        options = [int(c) for c in net.successors(int(route[k - 1]))
                   if net.kind[c] == LaneKind.CONNECTOR and net.turn[c] == int(turn)]
        if not options:
            return False
        if int(route[k]) in options:
            return True
        if st["grant"][-1] == route[k]:
            st["grant"][-1] = -1  # the reservation was for the old connector
        route[k:] = spawn.plan_route(net, options[0], self.rng, len(route) - k)
        return True

    # ------------------------------------------------------------------ views
    @property
    def map(self) -> WorldMap:
        """The static map of this episode."""
        return self._map

    @property
    def agents(self) -> Agents:
        """All agents except the ego (copies, safe to keep)."""
        st = self._state
        return Agents(st["xy"][:-1].copy(), st["yaw"][:-1].copy(), st["v"][:-1].copy(),
                      2 * st["hl"][:-1], 2 * st["hw"][:-1], st["akind"][:-1].copy(),
                      st["parked"][:-1].copy(), st["height"][:-1].copy())

    @property
    def agent_lanes(self) -> np.ndarray:
        """``(N,) int64`` current lane of each agent (-1: parked)."""
        return self._state["route"][:-1, 0].copy()

    @property
    def ego_pose(self) -> np.ndarray:
        """``(3,) float64`` ego centre and heading ``(x [m], y [m], yaw [rad])``."""
        st = self._state
        return np.array([st["xy"][-1, 0], st["xy"][-1, 1], st["yaw"][-1]])

    @property
    def ego_speed(self) -> float:
        """Ego speed [m/s]."""
        return float(self._state["v"][-1])

    @property
    def ego_steer(self) -> float:
        """Steering angle applied in the last step [rad]."""
        return self._steer

    @property
    def ego_size(self) -> tuple[float, float]:
        """``(length, width)`` of the ego [m]."""
        return (self.config["ego"]["length"], self.config["ego"]["width"])

    @property
    def lane_offset(self) -> float:
        """Signed distance of the ego centre from its route lane's centre-line [m], left +."""
        return self._lane_offset

    @property
    def route(self) -> np.ndarray:
        """``(ROUTE_LEN,) int64`` lanes the ego plans to follow, current lane first."""
        return self._state["route"][-1].copy()

    def route_polyline(self, ahead: float = 50.0, spacing: float = 1.0) -> np.ndarray:
        """Points of the ego route from its position on: ``(M, 2) float64`` [m]."""
        st, net = self._state, self._map.lanes
        d = np.arange(0.0, ahead + 1e-9, spacing)
        return np.array([route_point(st["route"][-1], st["s"][-1], float(k), net.pts, net.hdg,
                                     net.start, net.npts, net.ds, net.length)[:2] for k in d])

    def route_steer(self) -> float:
        """Steering angle [rad] that follows the ego's route: pure pursuit of the rear
        axle onto the route point :func:`~dstenv.sim.ego.pursuit_lookahead` ahead.

        The autopilot's rule, also used by the env's meta-actions: one rule, one home.
        """
        st, net, ego_cfg = self._state, self._map.lanes, self.config["ego"]
        x, y, yaw, v = st["xy"][-1, 0], st["xy"][-1, 1], st["yaw"][-1], st["v"][-1]
        half_wb = ego_cfg["wheelbase"] / 2
        # pure pursuit of the rear axle, which then stays on the lane in turns
        tx, ty, _ = route_point(st["route"][-1], st["s"][-1], pursuit_lookahead(v) - half_wb,
                                net.pts, net.hdg, net.start, net.npts, net.ds, net.length)
        return pure_pursuit(x - half_wb * np.cos(yaw), y - half_wb * np.sin(yaw), yaw,
                            (tx, ty), ego_cfg["wheelbase"], ego_cfg["max_steer"])

    def next_junction(self) -> tuple[float, Control, bool]:
        """The next junction on the ego's route, as a navigation system and the road
        signs tell it.

        Returns:
            ``(distance [m], control, green)``: route distance from the ego to the
            entry of the next junction connector (0 inside one; ``inf`` when the
            planned route holds none), its :class:`~dstenv.sim.lanes.Control`
            (``NONE`` when there is none), and whether a signal shows green for the
            ego's connector now (False for other controls).
        """
        st, net = self._state, self._map.lanes
        route = st["route"][-1]
        dist = -float(st["s"][-1])
        for lane in route:
            if lane < 0:
                break
            if net.kind[lane] == LaneKind.CONNECTOR:
                n = int(net.node[lane])
                control = Control(int(net.node_control[n]))
                green = control == Control.SIGNAL and signal_green(
                    int(net.group[lane]), self.time, float(net.node_phase[n]),
                    float(self.config["traffic"]["signal_green"]))
                return max(dist, 0.0), control, bool(green)
            dist += float(net.length[lane])
        return float("inf"), Control.NONE, False

    # ------------------------------------------------------------------ internals
    def _localise(self, u: float) -> None:
        """Find the ego on its route after it moved; re-plan when it left the route."""
        st, net = self._state, self._map.lanes
        route, s_old = st["route"][-1], st["s"][-1]
        x, y, yaw = st["xy"][-1, 0], st["xy"][-1, 1], st["yaw"][-1]
        geo = (net.pts, net.start, net.npts, net.ds)
        s, lat, dist = project_on_lane(*geo, route[0], x, y, s_old, 5.0)
        gain = s - s_old
        if s >= net.length[route[0]] - 1e-6 and route[1] >= 0:
            s1, lat1, d1 = project_on_lane(*geo, route[1], x, y, 0.0, 5.0)
            if d1 <= dist + 1e-9:
                gain = net.length[route[0]] - s_old + s1
                s, lat, dist = s1, lat1, d1
                route[:-1] = route[1:].copy()
                route[-1] = -1 if route[-2] < 0 else choose_successor(
                    route[-2], u, net.succ_ptr, net.succ, net.kind, net.turn, 0.0)
        _, _, lane_yaw = lane_pose(net.pts, net.hdg, net.start, net.npts, net.ds, route[0], s)
        heading_err = abs((yaw - lane_yaw + np.pi) % (2 * np.pi) - np.pi)
        if dist > 4.0 or heading_err > np.pi / 2:  # left the route: re-plan from here
            gain = 0.0
            found = spawn.nearest_lane(net, x, y, yaw)
            if found is not None:
                lane, s = found
                route[:] = spawn.plan_route(net, lane, self.rng, len(route))
                _, lat, _ = project_on_lane(*geo, lane, x, y, s, 1.0)
        st["s"][-1] = s
        self._lane_offset = float(lat)
        self.route_progress += float(gain)

    def _update_flags(self) -> None:
        st = self._state
        box = (*self.ego_pose, *self.ego_size)
        self.collision, self.off_road = hits(self._map, st["xy"][:-1], st["yaw"][:-1],
                                             st["hl"][:-1], st["hw"][:-1], box)

    def _ask_shadow(self, reset: bool = False) -> None:
        """Once per step (its stop clock advances), and afresh after a reset or a move."""
        if self.shadow is not None:
            self.shadow.update(self, reset)

    def _load_osm(self) -> WorldMap:
        from dstenv.sim.osm import load_osm, resolve_osm_file

        m = self.config["map"]
        path = resolve_osm_file(m["osm_file"], self._base_dir)
        wm = load_osm(path, resolution=m["resolution"], lane_width=m["osm_lane_width"],
                      margin=m["margin"], traffic=self.config["traffic"])
        # fixed seed: the same file gives the same street clutter
        wm.obstacles = street_clutter(wm, self.config["clutter"], np.random.default_rng(0))
        return wm
