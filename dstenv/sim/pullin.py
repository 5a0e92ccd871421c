"""Cars pulling into kerbside parking spaces (moving -> static), the reverse of
:func:`dstenv.sim.spawn.pull_out`.

Per step (:meth:`dstenv.sim.world.World.step`), with ``traffic.pull_in_rate`` > 0:

1. :func:`start_pull_ins`: each *eligible* car (a moving car, faster than 2 m/s, on
   the kerb-side lane of a road, not changing lanes, halted or double parked)
   decides to park with probability ``pull_in_rate * dt`` (Poisson draws, as
   pull-outs). It looks for a space ahead on its lane (:func:`find_space`): the
   nearest parking slot of the map (``meta["parking_slots"]``, placed by
   :mod:`dstenv.sim.parking` clear of junctions and crosswalks) between the distance
   it needs to stop braking at :data:`PICK_DECEL` (+ 3 m) and :data:`LOOK_AHEAD`
   (braking starts on the curve of ``PARK_DECEL``, or at once if it is already past
   it, at the constant deceleration that stops it at the target), where its own
   body fits: the target box plus a run-in of one car length behind it (it drives in
   forwards) is clear by :data:`CLEARANCE` of every agent, of the ground-level street
   clutter and of other cars' targets, and lies on kerbside ground (not road, not a
   building). The target offset puts the car's lane-side wheels 0-0.4 m beyond the
   road edge (measured on the map raster), the slot's own offset where it is in that
   range. No space: the car drives on.
2. The traffic step (:func:`dstenv.sim.traffic.traffic_step`) brakes it to a stop at
   the target and slides it sideways into the space (``park`` row of the state).
3. :func:`settle`: a car that stands in its space (speed 0, lateral offset reached,
   at the target or stopped there for :data:`SETTLE_TIME`) is parked: ``parked``,
   not ``mobile``, speed 0, aligned with its lane (the kerb). Its label turns from
   moving to static as its speed drops below the label threshold. One that stands
   still for :data:`GIVE_UP_TIME` before getting in gives up and drives on.
   For every car that parks, a parked car at least :data:`BALANCE_DIST` from the
   ego pulls out (:func:`dstenv.sim.spawn.pull_out`), so moving traffic stays as
   dense as it was; no row is ever added, so the number of agents is fixed.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from dstenv.sim import spawn
from dstenv.sim.lanes import LaneKind, lane_pose, project_on_lane
from dstenv.sim.placement import free_spot
from dstenv.sim.raster import lookup
from dstenv.sim.types import AgentKind, MapClass, WorldMap

__all__ = ["eligible", "find_space", "start_pull_ins", "settle", "LOOK_AHEAD",
           "CLEARANCE", "BALANCE_DIST"]

LOOK_AHEAD = 80.0  # [m] farthest space a car considers
CLEARANCE = 0.3  # [m] kept from bodies, clutter and other targets around the space
MIN_SPEED = 2.0  # [m/s] a car slower than this (queued, starting) does not decide to park
PICK_DECEL = 2.0  # [m/s^2] a space needs no harder braking than this (comfortable: 2.5)
SETTLE_TIME = 3.0  # [s] stopped short of its target but inside the space: parked there
GIVE_UP_TIME = 30.0  # [s] stopped this long before getting into the space: drives on
BALANCE_DIST = 60.0  # [m] a car that parks makes one this far from the ego pull out
_EDGE_MIN, _EDGE_MAX = -0.1, 0.3  # [m] lane-side wheels beyond the road edge


def eligible(st: dict[str, np.ndarray], world_map: WorldMap, i: int) -> bool:
    """Whether row ``i`` (not the ego) may decide to pull in now."""
    lane = int(st["route"][i, 0])
    return bool(st["mobile"][i] and st["akind"][i] == AgentKind.CAR and st["v"][i] > MIN_SPEED
                and st["lc"][i] == 0.0 and st["halt"][i] <= 0.0 and not st["hazard"][i]
                and st["park"][i, 0] < 0.0 and lane >= 0
                and world_map.lanes.kind[lane] == LaneKind.ROAD
                and world_map.lanes.rightmost[lane])


def _road_edge(world_map: WorldMap, x: float, y: float, h: float) -> float:
    """Distance [m] from the lane point ``(x, y)`` (heading ``h``) to the first non-road
    cell on its right (NaN when there is none within 4 m)."""
    q = np.arange(0.0, 4.0, 0.05)
    cls = lookup(world_map, np.stack([x + q * np.sin(h), y - q * np.cos(h)], -1))
    off = np.flatnonzero(cls != MapClass.ROAD)
    return float(q[off[0]]) if len(off) else float("nan")


def _corners(x: float, y: float, h: float, hl: float, hw: float, n: int = 5) -> np.ndarray:
    """``(3n, 2)`` points over a box: n along each long side and its middle."""
    a = np.linspace(-hl, hl, n)
    pts = [(a, np.full(n, b)) for b in (-hw, 0.0, hw)]
    lon = np.concatenate([p[0] for p in pts])
    lat = np.concatenate([p[1] for p in pts])
    c, s = np.cos(h), np.sin(h)
    return np.stack([x + lon * c - lat * s, y + lon * s + lat * c], -1)


def find_space(world_map: WorldMap, st: dict[str, np.ndarray], i: int
               ) -> tuple[float, float] | None:
    """The space row ``i`` pulls into: ``(s [m] on its lane, lateral offset [m], left +)``
    of its centre there, or None (see the module doc for the rules)."""
    net = world_map.lanes
    slots = world_map.meta.get("parking_slots")
    if slots is None or len(slots) == 0:
        return None
    ln, s_i, v = int(st["route"][i, 0]), float(st["s"][i]), float(st["v"][i])
    hl, hw = float(st["hl"][i]), float(st["hw"][i])
    d_min = v * v / (2.0 * PICK_DECEL) + 3.0
    # slots ahead on the right, roughly (the lane may bend): the rest are never checked
    rel = slots[:, :2] - st["xy"][i]
    c, s = np.cos(st["yaw"][i]), np.sin(st["yaw"][i])
    lon, side = rel[:, 0] * c + rel[:, 1] * s, rel[:, 1] * c - rel[:, 0] * s
    near = np.flatnonzero((lon > d_min - 5.0) & (lon < LOOK_AHEAD + 5.0) & (side < -0.5)
                          & (side > -8.0))
    if len(near) == 0:
        return None
    d = np.full(len(slots), np.inf)
    d[near] = np.hypot(rel[near, 0], rel[near, 1])
    geo = (net.pts, net.start, net.npts, net.ds)
    others = np.flatnonzero(np.arange(len(st["v"])) != i)
    busy = np.flatnonzero(st["park"][:, 0] >= 0.0)  # targets of cars already pulling in
    tgt = np.zeros((len(busy), 2))
    for k, j in enumerate(busy):
        tx, ty, th = lane_pose(net.pts, net.hdg, net.start, net.npts, net.ds,
                               int(st["route"][j, 0]), float(st["park"][j, 0]))
        tgt[k] = tx - st["park"][j, 1] * np.sin(th), ty + st["park"][j, 1] * np.cos(th)
    obs = world_map.obstacles
    low = np.flatnonzero(obs.z_min < 1.0) if len(obs) else np.zeros(0, np.int64)
    for k in near[np.argsort(d[near])]:
        sx, sy = slots[k, :2]
        s_c, lat_c, dist = project_on_lane(*geo, ln, sx, sy, s_i + d[k], d[k] + 10.0)
        if not (d_min <= s_c - s_i <= LOOK_AHEAD and hl + 1.0 < s_c < net.length[ln] - hl - 1.0
                and lat_c < 0.0 and dist < 6.0):
            continue
        x, y, h = lane_pose(net.pts, net.hdg, net.start, net.npts, net.ds, ln, s_c)
        edge = _road_edge(world_map, x, y, h)
        if not 0.8 < edge < 2.5 or -lat_c - edge > 3.5:
            continue
        inset = min(max(-lat_c - edge - hw, _EDGE_MIN), _EDGE_MAX)  # lane-side wheels
        lat_t = -(edge + inset + hw)
        cx, cy = x - lat_t * np.sin(h), y + lat_t * np.cos(h)
        # the space and the run-in behind it (one car length): clear of everything
        bx, by = cx - hl * np.cos(h), cy - hl * np.sin(h)
        if not free_spot(st["xy"][others], st["yaw"][others], st["hl"][others],
                         st["hw"][others], len(others), bx, by, h, 4.0 * hl, 2.0 * hw,
                         CLEARANCE):
            continue
        if len(low) and not free_spot(obs.xy[low], obs.yaw[low], obs.length[low] / 2,
                                      obs.width[low] / 2, len(low), bx, by, h, 4.0 * hl,
                                      2.0 * hw, CLEARANCE):
            continue
        if len(tgt) and np.hypot(*(tgt - (cx, cy)).T).min() < 2.0 * hl + 5.0 + CLEARANCE:
            continue
        ground = lookup(world_map, _corners(cx, cy, h, hl + CLEARANCE, hw - 0.15))
        run_in = lookup(world_map, _corners(bx, by, h, 2.0 * hl, hw))
        if (ground != MapClass.INTERMEDIATE).any() or (run_in == MapClass.BUILDING).any() \
                or (run_in == MapClass.NONE).any():
            continue
        return float(s_c), float(lat_t)
    return None


def start_pull_ins(world_map: WorldMap, st: dict[str, np.ndarray], rate: float, dt: float,
                   rng: np.random.Generator) -> int:
    """Draw which cars decide to park this step (``rate`` [1/s] per car: a Poisson number
    of decisions over all non-ego rows, each for a random row; a row that is not
    :func:`eligible` ignores it, so every eligible car decides at ``rate``) and give
    those that find a space their target (``park`` row). Returns how many started.

    (Drawing over all rows, not over the eligible ones, keeps the step cheap: nothing
    is computed for the ~99 % of steps without a decision.)"""
    n = len(st["v"]) - 1
    started = 0
    for _ in range(rng.poisson(rate * dt * n) if n > 0 else 0):
        i = int(rng.integers(n))
        if not eligible(st, world_map, i):
            continue
        space = find_space(world_map, st, i)
        if space is not None:
            st["park"][i] = space
            st["grant"][i], st["req_t"][i], st["stop_clock"][i] = -1, np.inf, 0.0
            started += 1
    return started


def settle(world_map: WorldMap, st: dict[str, np.ndarray], cfg: dict[str, Any],
           rng: np.random.Generator, k: int) -> list[int]:
    """Park the cars that stand in their space, let those stuck outside give up, and
    balance every new parked car by a far one pulling out. Returns the rows parked."""
    rows = np.flatnonzero(st["park"][:-1, 0] >= 0.0)
    net = world_map.lanes
    done = []
    for i in rows:
        inside = abs(st["lat"][i] - st["park"][i, 1]) < 0.02
        at = st["park"][i, 0] - st["s"][i] < 0.05
        if st["v"][i] == 0.0 and inside and (at or st["still"][i] >= SETTLE_TIME):
            # (a far car leaves first, so it is never this one)
            for _ in range(5):  # a few draws: the drawn car may have no lane beside it
                if spawn.pull_out(world_map, st, cfg, rng, k,
                                  min_ego_dist=BALANCE_DIST) is not None:
                    break
            _, _, h = lane_pose(net.pts, net.hdg, net.start, net.npts, net.ds,
                                int(st["route"][i, 0]), float(st["s"][i]))
            st["parked"][i], st["mobile"][i] = True, False
            st["yaw"][i], st["v"][i] = h, 0.0
            st["route"][i] = -1
            st["park"][i] = (-1.0, 0.0)
            st["lat"][i] = st["lat_goal"][i] = 0.0
            st["grant"][i], st["req_t"][i], st["stop_clock"][i], st["still"][i] = \
                -1, np.inf, 0.0, 0.0
            done.append(int(i))
        elif st["still"][i] >= GIVE_UP_TIME and not inside:
            st["park"][i] = (-1.0, 0.0)
            st["lat_goal"][i], st["lc"][i] = 0.0, -1.0  # back to the lane centre
    return done
