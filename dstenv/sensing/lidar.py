"""A 2-D scanning LIDAR: exact ray casting against buildings and agent footprints.

Beam ``k`` of ``B`` points at the ego-frame angle ``-fov/2 + k * fov/B`` (so with
the default 360 deg the beams cover ``[-pi, pi)`` and beam ``B/2`` looks straight
ahead). Each beam returns the distance to the first building or agent it meets:

* buildings, ``buildings="polygons"``: exact ray / polygon-edge intersection with the
  footprints of ``WorldMap.buildings``. Edges are binned by the beams their angular
  extent covers, so the cost grows with the number of (edge, beam) pairs actually
  facing each other, not with ``edges x beams``.
* buildings, ``buildings="raster"``: exact Amanatides-Woo traversal of
  ``WorldMap.raster`` up to the first :attr:`MapClass.BUILDING` cell.
* agents: exact ray / oriented-box intersection (the four edges of
  :meth:`Agents.corners`), binned by angle like the polygons.
* street clutter (``WorldMap.obstacles``): the same exact box intersection, for the
  boxes that the scan plane cuts (``z_min <= plane_height <= z_max``: a trunk
  occludes, the crown above it does not). They are selected once per map.

Noise and dropout come only from the generator passed to :meth:`Lidar.sweep`."""

from __future__ import annotations

import math
import weakref
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np

from dstenv.grid import GridSpec
from dstenv.sensing.config import lidar_config
from dstenv.sensing.raycast import sensor_grid
from dstenv.sim.types import Agents, MapClass, WorldMap

__all__ = ["Lidar", "Sweep", "HIT_NONE", "HIT_BUILDING", "HIT_OBSTACLE"]

#: ``Sweep.hit_id`` of a beam without return.
HIT_NONE: int = -1
#: ``Sweep.hit_id`` of a beam that ended on a building.
HIT_BUILDING: int = -2
#: ``Sweep.hit_id`` of a beam that ended on street clutter (``WorldMap.obstacles``).
HIT_OBSTACLE: int = -3

_NONE_F = np.zeros(0)
_NONE_B = np.zeros(0, dtype=bool)
_NO_IDS = np.zeros(0, dtype=np.int32)  # box hit ids = box index
_EDGE_CACHE = 64  # maps whose building edges a Lidar keeps (a map pool reuses them)


@dataclass
class Sweep:
    """One LIDAR revolution.

    Attributes:
        angles: ``(B,) float64`` beam directions in the ego frame [rad] (0 = forward,
            counter-clockwise positive).
        ranges: ``(B,) float64`` distance from the sensor to the return [m];
            ``max_range`` for a beam without return, NaN for a dropped beam.
        hit: ``(B,) bool`` the beam returned from an obstacle.
        hit_id: ``(B,) int32`` what it hit: :data:`HIT_NONE` (-1),
            :data:`HIT_BUILDING` (-2), :data:`HIT_OBSTACLE` (-3, street clutter) or
            the index ``k >= 0`` of the agent.
        points: ``(B, 2) float64`` ego-frame ``(x, y)`` of the returns [m]; NaN rows
            where ``hit`` is false.
        valid: ``(B,) bool`` the beam produced a measurement (false: dropout).
        origin: ``(2,) float64`` sensor position in the ego frame [m] (the mount).
        max_range: the sensor's range [m].
    """

    angles: np.ndarray
    ranges: np.ndarray
    hit: np.ndarray
    hit_id: np.ndarray
    points: np.ndarray
    valid: np.ndarray
    origin: np.ndarray
    max_range: float

    def sensor_grid(self, spec: GridSpec) -> np.ndarray:
        """The sweep cast into an ego grid: ``(H, W) uint8`` (see :func:`sensor_grid`)."""
        return sensor_grid(self.angles, self.ranges, self.hit, spec, self.max_range,
                           origin=(float(self.origin[0]), float(self.origin[1])))


class Lidar:
    """A simulated 2-D LIDAR mounted on the ego.

    Args:
        config: overrides of :func:`dstenv.sensing.config.default_lidar_config`
            (``beams``, ``fov`` [deg], ``max_range`` [m], ``range_noise`` [m],
            ``dropout``, ``mount_x`` / ``mount_y`` [m], ``plane_height`` [m],
            ``buildings``).

    Raises:
        dstenv.config.ConfigError: on an unknown key or an invalid value.
    """

    def __init__(self, config: Mapping[str, Any] | None = None) -> None:
        self.config = lidar_config(config)
        c = self.config
        self.beams = int(c["beams"])
        self.max_range = float(c["max_range"])
        fov = math.radians(c["fov"])
        self.periodic = c["fov"] == 360.0
        self.dtheta = fov / self.beams
        self.theta0 = -fov / 2
        self.angles = self.theta0 + self.dtheta * np.arange(self.beams, dtype=np.float64)
        self.mount = np.array([c["mount_x"], c["mount_y"]], dtype=np.float64)
        self._cos, self._sin = np.cos(self.angles), np.sin(self.angles)  # beam directions
        self._map: WorldMap | None = None
        self._edge_cache: dict[int, tuple] = {}  # id(map) -> (ref, edges, starts, boxes)
        self._edges, self._starts = np.zeros((0, 4)), np.zeros(1, np.int64)
        self._boxes = np.zeros((0, 4))
        self._obs_map: WorldMap | None = None
        self._obs: tuple[np.ndarray, ...] = ()

    def __getstate__(self) -> dict[str, Any]:  # the cache's weak references do not pickle
        return {**self.__dict__, "_edge_cache": {}}

    def sweep(
        self, world_map: WorldMap, agents: Agents, pose: np.ndarray, rng: np.random.Generator
    ) -> Sweep:
        """Cast all beams from the sensor mounted on the ego at ``pose``.

        Args:
            world_map: the static map (buildings occlude).
            agents: the other road users (their oriented footprints occlude).
            pose: ``(3,)`` ego world pose ``(x [m], y [m], yaw [rad])``.
            rng: source of range noise and dropout (untouched when both are 0).

        Returns:
            A :class:`Sweep`.
        """
        pose = np.asarray(pose, dtype=np.float64)
        if pose.shape != (3,) or not np.all(np.isfinite(pose)):
            raise ValueError(f"sweep: pose must be a finite (3,) array (x, y, yaw), got {pose!r}")
        px, py, yaw = (float(v) for v in pose)
        cy, sy = math.cos(yaw), math.sin(yaw)
        sx = px + cy * self.mount[0] - sy * self.mount[1]
        sy_ = py + sy * self.mount[0] + cy * self.mount[1]
        best = np.full(self.beams, np.inf)
        best_id = np.full(self.beams, HIT_NONE, dtype=np.int32)
        geo = (sx, sy_, cy, sy, self.theta0, self.dtheta, self.periodic, self.max_range,
               self._cos, self._sin, best, best_id)

        mode = self.config["buildings"]
        if mode == "auto":
            mode = "polygons" if world_map.buildings else "raster"
        if mode == "polygons":
            self._load_polygons(world_map)
            _cast_edges(self._edges, self._starts, self._boxes, *geo)
        else:
            raster = np.ascontiguousarray(world_map.raster, dtype=np.uint8)
            _cast_raster(raster, float(world_map.origin[0]), float(world_map.origin[1]),
                         float(world_map.resolution), np.uint8(MapClass.BUILDING), *geo)
        obs = self._load_obstacles(world_map)
        if len(obs[1]):
            _cast_boxes(*obs, np.full(len(obs[1]), HIT_OBSTACLE, np.int32), *geo)
        if len(agents):
            f64 = np.float64
            _cast_boxes(np.ascontiguousarray(agents.xy, f64), np.ascontiguousarray(agents.yaw, f64),
                        np.ascontiguousarray(agents.length, f64),
                        np.ascontiguousarray(agents.width, f64), _NO_IDS, *geo)
        return self._measure(best, best_id, rng)

    def _load_obstacles(self, world_map: WorldMap) -> tuple[np.ndarray, ...]:
        """The clutter boxes cut by the scan plane, selected once per map."""
        if self._obs_map is not world_map:
            o = world_map.obstacles
            keep = o.at_height(float(self.config["plane_height"]))
            f64 = np.float64
            self._obs = tuple(np.ascontiguousarray(a[keep], f64)
                              for a in (o.xy, o.yaw, o.length, o.width))
            self._obs_map = world_map
        return self._obs

    def _measure(self, best: np.ndarray, best_id: np.ndarray, rng: np.random.Generator) -> Sweep:
        c, b = self.config, self.beams
        noise = rng.normal(0.0, c["range_noise"], b) if c["range_noise"] > 0 else _NONE_F
        drop = rng.random(b) < c["dropout"] if c["dropout"] > 0 else _NONE_B
        ranges = np.empty(b)
        hit = np.empty(b, dtype=bool)
        valid = np.empty(b, dtype=bool)
        points = np.empty((b, 2))
        _finish(best, best_id, self.max_range, noise, drop, self._cos, self._sin,
                float(self.mount[0]), float(self.mount[1]), ranges, hit, valid, points)
        return Sweep(self.angles.copy(), ranges, hit, best_id, points, valid, self.mount.copy(),
                     self.max_range)

    def _load_polygons(self, world_map: WorldMap) -> None:
        """Flatten the building polygons into an edge list once per map (the last
        :data:`_EDGE_CACHE` maps are kept: a map pool cycles through a few)."""
        if self._map is world_map and len(self._starts) == len(world_map.buildings) + 1:
            return
        cached = self._edge_cache.get(id(world_map))
        if cached is not None and cached[0]() is world_map:
            _, self._edges, self._starts, self._boxes = cached
            self._map = world_map
            return
        polys = [np.asarray(poly, dtype=np.float64) for poly in world_map.buildings]
        for b, poly in enumerate(polys):
            if poly.ndim != 2 or poly.shape[1] != 2 or poly.shape[0] < 3:
                raise ValueError(f"WorldMap.buildings[{b}]: expected a (K>=3, 2) polygon, "
                                 f"got shape {poly.shape}")
        if polys:  # all polygons at once: each vertex with the next one of its polygon
            n = np.array([len(poly) for poly in polys], dtype=np.int64)
            first = np.cumsum(n) - n
            pts = np.concatenate(polys)
            nxt = np.arange(1, len(pts) + 1)
            nxt[first + n - 1] = first
            e = np.concatenate([pts, pts[nxt]], axis=1)
            keep = np.any(e[:, :2] != e[:, 2:], axis=1)  # drop the closing duplicate vertex
            counts = np.bincount(np.repeat(np.arange(len(polys)), n)[keep], minlength=len(polys))
            self._edges = np.ascontiguousarray(e[keep])
            self._starts = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
            self._boxes = np.concatenate([np.minimum.reduceat(pts, first),
                                          np.maximum.reduceat(pts, first)], axis=1)
        else:
            self._edges, self._starts = np.zeros((0, 4)), np.zeros(1, np.int64)
            self._boxes = np.zeros((0, 4))
        self._map = world_map
        if len(self._edge_cache) >= _EDGE_CACHE:
            self._edge_cache.pop(next(iter(self._edge_cache)))
        self._edge_cache[id(world_map)] = (weakref.ref(world_map), self._edges, self._starts,
                                           self._boxes)  # weak: never keeps ~13 MB maps alive


@numba.njit(cache=True, inline="always")
def _cast_segment(ax, ay, bx, by, aa, ab, hid, theta0, dtheta, periodic, max_range, cos_t,
                  sin_t, best, best_id):  # pragma: no cover - numba
    """Nearest hits of the beams with one segment given in the sensor frame; ``aa``,
    ``ab``: ``atan2`` of its ends (a vertex shared by two segments costs one)."""
    nb = cos_t.shape[0]
    two_pi = 2.0 * math.pi
    period = two_pi / dtheta  # beams per full turn (== nb when periodic)
    ex = bx - ax
    ey = by - ay
    # beam-index interval covered by the segment (the short arc between its ends)
    fa = (aa - theta0) % two_pi
    fb = (ab - theta0) % two_pi
    d = fb - fa
    if d > math.pi:
        d -= two_pi
    elif d < -math.pi:
        d += two_pi
    lo = (fa if d >= 0 else fb) / dtheta
    hi = lo + abs(d) / dtheta
    # past theta0 + 2 pi: beam index modulo nb, or (partial fov) a second pass
    for wrap in range(2 if not periodic and hi >= period - 1.0 else 1):
        k_lo = int(math.floor(lo - wrap * period))
        k_hi = int(math.floor(hi - wrap * period)) + 1
        k_lo, k_hi = (k_lo, k_hi) if periodic else (max(k_lo, 0), min(k_hi, nb - 1))
        for kk in range(k_lo, k_hi + 1):
            k = kk % nb if periodic else kk
            ux = cos_t[k]
            uy = sin_t[k]
            den = ux * ey - uy * ex
            if den == 0.0:
                continue
            t = (ax * ey - ay * ex) / den
            s = (ax * uy - ay * ux) / den
            if t >= 0.0 and 0.0 <= s <= 1.0 and t < best[k]:
                best[k] = t
                best_id[k] = hid


@numba.njit(cache=True)
def _cast_edges(edges, starts, boxes, sx, sy, cyaw, syaw, theta0, dtheta, periodic, max_range,
                cos_t, sin_t, best, best_id):  # pragma: no cover - numba
    """Buildings: polygon b owns ``edges[starts[b]:starts[b+1]]`` (rows ``x1, y1, x2, y2``)
    and has the bounding box ``boxes[b]`` (``xmin, ymin, xmax, ymax``), all world frame."""
    r2 = max_range * max_range
    for g in range(boxes.shape[0]):
        dx = max(boxes[g, 0] - sx, 0.0, sx - boxes[g, 2])
        dy = max(boxes[g, 1] - sy, 0.0, sy - boxes[g, 3])
        if dx * dx + dy * dy > r2:
            continue
        px = py = pa = np.nan  # end of the previous edge in the sensor frame, its atan2
        for e in range(starts[g], starts[g + 1]):
            x1 = edges[e, 0] - sx
            y1 = edges[e, 1] - sy
            x2 = edges[e, 2] - sx
            y2 = edges[e, 3] - sy
            ax = cyaw * x1 + syaw * y1
            ay = -syaw * x1 + cyaw * y1
            bx = cyaw * x2 + syaw * y2
            by = -syaw * x2 + cyaw * y2
            # a polygon's edges chain: the start is the previous end, the same numbers
            # (equal non-zero floats are the same bits; atan2 tells -0.0 from 0.0)
            same = ax == px and ay == py and ax != 0.0 and ay != 0.0
            aa = pa if same else math.atan2(ay, ax)
            pa = math.atan2(by, bx)
            px = bx
            py = by
            _cast_segment(ax, ay, bx, by, aa, pa, -2, theta0, dtheta, periodic, max_range,
                          cos_t, sin_t, best, best_id)


@numba.njit(cache=True)
def _cast_boxes(xy, yaw, length, width, ids, sx, sy, cyaw, syaw, theta0, dtheta, periodic,
                max_range, cos_t, sin_t, best, best_id):  # pragma: no cover - numba
    """Oriented boxes (agents, clutter): the four edges of each footprint; hit id =
    ``ids[k]``, or the box index ``k`` when ``ids`` is empty."""
    cx = np.empty(4)
    cy = np.empty(4)
    ca4 = np.empty(4)  # atan2 of each corner
    for k in range(xy.shape[0]):
        hl = 0.5 * length[k]
        hw = 0.5 * width[k]
        dx = xy[k, 0] - sx
        dy = xy[k, 1] - sy
        if math.sqrt(dx * dx + dy * dy) - math.sqrt(hl * hl + hw * hw) > max_range:
            continue
        # centre and heading in the sensor frame
        lx = cyaw * dx + syaw * dy
        ly = -syaw * dx + cyaw * dy
        ca = math.cos(yaw[k]) * cyaw + math.sin(yaw[k]) * syaw
        sa = math.sin(yaw[k]) * cyaw - math.cos(yaw[k]) * syaw
        for q in range(4):
            ol = hl if q == 0 or q == 3 else -hl  # corners counter-clockwise, as Agents.corners
            ow = hw if q < 2 else -hw
            cx[q] = lx + ca * ol - sa * ow
            cy[q] = ly + sa * ol + ca * ow
            ca4[q] = math.atan2(cy[q], cx[q])
        hid = ids[k] if ids.shape[0] else k
        for q in range(4):
            p = (q + 1) % 4
            _cast_segment(cx[q], cy[q], cx[p], cy[p], ca4[q], ca4[p], hid, theta0, dtheta,
                          periodic, max_range, cos_t, sin_t, best, best_id)


@numba.njit(cache=True)
def _finish(best, best_id, max_range, noise, drop, cos_t, sin_t, mx, my,
            ranges, hit, valid, points):  # pragma: no cover - numba
    """Turn nearest-hit distances into measurements: noise, dropout, points."""
    for k in range(best.shape[0]):
        h = best[k] <= max_range
        r = best[k] if h else max_range
        if h and noise.shape[0]:
            r = min(max(r + noise[k], 0.0), max_range)
        v = not (drop.shape[0] and drop[k])
        if not v:
            h = False
            r = np.nan
        if not h:
            best_id[k] = -1
        ranges[k] = r
        hit[k] = h
        valid[k] = v
        points[k, 0] = mx + r * cos_t[k] if h else np.nan
        points[k, 1] = my + r * sin_t[k] if h else np.nan


@numba.njit(cache=True)
def _cast_raster(raster, x0, y0, res, building, sx, sy, cyaw, syaw, theta0, dtheta, periodic,
                 max_range, cos_t, sin_t, best, best_id):  # pragma: no cover - numba
    """Distance along each beam to the first building cell (exact grid traversal)."""
    hm, wm = raster.shape
    u0 = (sx - x0) / res  # column coordinate
    v0 = (sy - y0) / res  # row coordinate
    for k in range(cos_t.shape[0]):
        ux = cyaw * cos_t[k] - syaw * sin_t[k]  # world direction of the beam
        uy = syaw * cos_t[k] + cyaw * sin_t[k]
        c = int(math.floor(u0))
        r = int(math.floor(v0))
        sc = 1 if ux > 0 else -1
        sr = 1 if uy > 0 else -1
        # metres along the beam to the next column / row boundary, and between boundaries
        if ux != 0.0:
            tdc = res / abs(ux)
            tmc = ((c + 1 - u0) if ux > 0 else (u0 - c)) * tdc
        else:
            tdc = np.inf
            tmc = np.inf
        if uy != 0.0:
            tdr = res / abs(uy)
            tmr = ((r + 1 - v0) if uy > 0 else (v0 - r)) * tdr
        else:
            tdr = np.inf
            tmr = np.inf
        t = 0.0
        while t <= max_range and t < best[k]:
            if 0 <= r < hm and 0 <= c < wm:
                if raster[r, c] == building:
                    best[k] = t
                    best_id[k] = -2
                    break
            elif ((c < 0 and sc < 0) or (c >= wm and sc > 0)
                  or (r < 0 and sr < 0) or (r >= hm and sr > 0)):
                break  # left the raster for good
            if tmc < tmr:
                t = tmc
                tmc += tdc
                c += sc
            else:
                t = tmr
                tmr += tdr
                r += sr
