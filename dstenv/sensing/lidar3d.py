"""A spinning 64-channel 3-D LIDAR (like KITTI's Velodyne HDL-64E) for the 2-D world.

Geometry. The sensor sits ``mount_height`` above the road at the ego's ``mount_x,
mount_y``; channel ``c`` of ``C`` has the elevation ``top - c (top - bottom) / (C-1)``
and fires every ``azimuth_step``; column ``j`` looks at the azimuth
``pi - j step`` (clockwise, as a Velodyne spins, starting behind the car). Everything
is a vertical prism over the world's footprints, heights from the occluder contract
of :mod:`dstenv.sim.types`: buildings ``[0, building_heights]``, agents
``[0, height]``, clutter ``[z_min, z_max]``, the road ``z = 0`` and
:attr:`MapClass.INTERMEDIATE` ground raised by ``kerb_height`` (its kerb is a
vertical face).

Exact ray casting. With ``t`` the horizontal distance along a column, a channel's
beam is at height ``z(t) = H + t tan(elevation)``. A box is hit at the first ``t``
of its slab interval ``[t_in, t_out]`` where ``z(t)`` lies in its height range (side
face, roof or underside); a building wall where an edge is crossed with ``z`` in
``[0, h]``; the ground where ``z`` reaches the kerb top over a raised cell (walked
with an exact grid traversal between the heights ``kerb`` and 0) or 0 on the road.
The kernels live in :mod:`dstenv.sensing.cast3d`, which tests each occluder only
against the columns and channels that can reach it (same results, ~10x faster).

Measurement. Slant range ``t / cos(elevation)`` with Gaussian noise, returns beyond
``max_range`` or closer than ``min_range`` (the blind zone) discarded, dropout,
returns on agents that fade with range and incidence (:mod:`dstenv.sensing.fading`,
``fade_range``, ``fade_sigma``; off by default), and
a reflectance from the surface material times a fixed per-channel gain (a
calibration table seeded by ``channel_seed``) with noise.

Motion skew. The turn takes ``1 / spin_rate``; column ``j`` fires at
``tau = -azimuth / (2 pi spin_rate)`` relative to the sweep's reference time (the
front, where KITTI triggers its camera), from where the ego is then (constant speed
and yaw rate), and its point is expressed in the sensor frame of that instant, as
raw Velodyne data are. The rest of the world is frozen during the turn.

Output: ``(N, 4) float32`` rows ``(x, y, z, reflectance)`` in the Velodyne frame
(x forward, y left, z up from the sensor): the KITTI ``.bin`` layout. All randomness
comes from the generator passed to :meth:`Hdl64.sweep`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np

from dstenv.dst import SensorState
from dstenv.grid import GridSpec
from dstenv.sensing.cast3d import cast_boxes, cast_ground, cast_walls, column_index
from dstenv.sensing.cloud import cloud_sensor_grid, ray_config
from dstenv.sensing.config import lidar_config
from dstenv.sensing.draws import (
    beam_dropout,
    beam_normal_rest,
    beam_normal_words,
    stream_keys,
)
from dstenv.sensing.fading import fade_returns
from dstenv.sensing.ground import CloudError, ground_config
from dstenv.sensing.raised import raised_distance
from dstenv.sensing.scene3d import (AGENT, BUILDING, REFLECTANCE, SURFACES, box_table,
                                    building_table, clutter_table)
from dstenv.sim.types import Agents, MapClass, WorldMap

__all__ = ["Hdl64", "Cloud", "SURFACES", "REFLECTANCE"]

#: Blocks of ``2**DIST_SHIFT`` cells a side for the ground walk's distance bound
#: (:func:`~dstenv.sensing.raised.raised_distance`): 2 x 2 blocks cut the bound's cost
#: per fresh map ~3x (18 -> 6 ms on the default city's 5.7 M cells) for ~2 % more time
#: in the ground walk of a sweep; the returns are the same.
DIST_SHIFT = 1


@dataclass
class Cloud:
    """One sweep of the 3-D LIDAR.

    Attributes:
        points: ``(N, 4) float32`` x, y, z [m] in the Velodyne frame and reflectance
            in [0, 1] (KITTI ``.bin`` rows).
        channel: ``(N,) int16`` channel of each point (0 = highest).
        column: ``(N,) int32`` azimuth column of each point.
        surface: ``(N,) uint8`` index into :data:`SURFACES`.
        index: ``(N,) int32`` agent / clutter / building index (-1 for the ground).
        mount: ``(2,) float64`` sensor position in the ego frame [m].
        config: the ``lidar.hdl64`` section used.
        shape: ``(columns, channels)`` beams of the sweep.
    """

    points: np.ndarray
    channel: np.ndarray
    column: np.ndarray
    surface: np.ndarray
    index: np.ndarray
    mount: np.ndarray
    config: dict[str, Any]
    shape: tuple[int, int]

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def dense(self) -> np.ndarray:
        """``(columns * channels, 4) float32`` one row per beam (column-major), NaN where
        there is no return: a fixed shape that stacks across sweeps."""
        out = np.full((self.shape[0] * self.shape[1], 4), np.nan, np.float32)
        out[self.column.astype(np.int64) * self.shape[1] + self.channel] = self.points
        return out

    def sensor_grid(self, spec: GridSpec) -> np.ndarray:
        """``(H, W) uint8`` sensor grid by :func:`dstenv.sensing.cloud.cloud_sensor_grid`
        (ground removal, one ray per point), the road KITTI scans take; the points are
        shifted by the mount so the grid stays ego-centred. A scan without a usable
        ground (every beam dropped, a mount below the candidates' height...) says nothing:
        every cell UNKNOWN (it raised mid-episode)."""
        try:
            return cloud_sensor_grid(self.points, spec, self.config["ground"],
                                     self.config["rays"],
                                     offset=(float(self.mount[0]), float(self.mount[1])))[0]
        except CloudError:
            return np.full(spec.shape, SensorState.UNKNOWN, np.uint8)


class Hdl64:
    """A simulated HDL-64E-like LIDAR.

    Args:
        config: overrides of the ``lidar`` section
            (:func:`dstenv.sensing.config.default_lidar_config`); its ``hdl64``
            sub-section and ``mount_x`` / ``mount_y`` are used.

    Raises:
        dstenv.config.ConfigError: an unknown key or a bad value.
    """

    def __init__(self, config: Mapping[str, Any] | None = None) -> None:
        full = lidar_config(config)
        # the road's sections merged and marked once, not again in every sensor_grid
        # call (the same values: a shallow copy, the caller's section is not touched)
        c = self.config = dict(full["hdl64"])
        c["ground"] = ground_config(c["ground"])
        c["rays"] = ray_config(c["rays"])
        self.mount = np.array([full["mount_x"], full["mount_y"]], dtype=np.float64)
        n = int(c["channels"])
        self.elevation = np.deg2rad(np.linspace(c["elevation_top"], c["elevation_bottom"], n))
        self.slope = np.tan(self.elevation)
        self._neg_slope = -self.slope  # increasing: the channel search of cast3d
        self.columns = int(round(360.0 / c["azimuth_step"]))
        self.azimuth = math.pi - np.deg2rad(c["azimuth_step"]) * np.arange(self.columns)
        # firing time of each column relative to the front [s]
        self._tau = (-self.azimuth / (2 * math.pi * c["spin_rate"]) if c["spin_rate"] > 0
                     else np.zeros(self.columns))
        self._cos_az, self._sin_az = np.cos(self.azimuth), np.sin(self.azimuth)
        self._cos_el, self._sin_el = np.cos(self.elevation), np.sin(self.elevation)
        gain_rng = np.random.default_rng(int(c["channel_seed"]))
        self.gain = gain_rng.uniform(0.75, 1.25, n)  # per-channel intensity calibration
        self._sec_el = 1.0 / self._cos_el  # horizontal -> slant range, by a product
        self._albedo = np.ascontiguousarray(np.outer(REFLECTANCE, self.gain))  # (surface, channel)
        self._map: WorldMap | None = None
        self._walls: tuple[np.ndarray, ...] = ()
        self._clutter = np.zeros((0, 11))  # the map's box rows (static: once per map)
        self._raster = np.zeros((0, 0), np.uint8)
        self._dist = np.zeros((0, 0), np.uint8)
        self._best = np.empty((self.columns, n))  # nearest hit per beam [m], horizontal
        self._surf = np.empty((self.columns, n), np.int16)  # read only where best < inf
        self._idx = np.empty((self.columns, n), np.int32)

    @property
    def beams(self) -> int:
        """Beams per sweep (channels x columns)."""
        return len(self.elevation) * self.columns

    def sweep(self, world_map: WorldMap, agents: Agents, pose: np.ndarray,
              rng: np.random.Generator, speed: float = 0.0, yaw_rate: float = 0.0) -> Cloud:
        """One turn from the ego at ``pose``.

        Args:
            world_map: buildings (with heights), clutter, ground raster and kerb.
            agents: other road users (footprints and heights).
            pose: ``(3,)`` ego world pose at the sweep's reference time.
            rng: source of noise, dropout and reflectance noise.
            speed: ego speed [m/s] and ``yaw_rate`` [rad/s] for the motion skew.

        Returns:
            A :class:`Cloud`.
        """
        c = self.config
        pose = np.asarray(pose, dtype=np.float64)
        if pose.shape != (3,) or not np.isfinite(pose).all():
            raise ValueError(f"Hdl64.sweep: pose must be a finite (3,) array, got {pose!r}")
        # sensor pose per column (constant speed and yaw rate; arc integrated exactly)
        ox, oy, world_az, ux, uy = _column_poses(pose, float(speed), float(yaw_rate), self._tau,
                                                 self.azimuth, self.mount)
        if self._map is not world_map:  # static geometry, flattened once per map
            self._walls = building_table(world_map)
            self._clutter = clutter_table(world_map)
            self._raster = np.ascontiguousarray(world_map.raster, dtype=np.uint8)
            self._dist = raised_distance(self._raster, MapClass.INTERMEDIATE, DIST_SHIFT)
            self._map = world_map
        boxes = box_table(agents, self._clutter, c["vehicle_shape"] == "car")
        edges, starts, circles, heights = self._walls
        best, surf, idx = self._best, self._surf, self._idx  # reused: no page faults
        best.fill(np.inf)  # surf and idx are written with every finite best
        h_max = c["max_range"]  # a slant range bounds the horizontal one
        mount = float(c["mount_height"])
        cols = column_index(ox, oy, world_az)
        cast_boxes(boxes, *cols, ox, oy, ux, uy, self.slope, self._neg_slope, mount, h_max,
                   best, surf, idx)
        cast_walls(edges, starts, circles, heights, BUILDING, *cols, ox, oy, ux, uy,
                   self.slope, self._neg_slope, mount, h_max, best, surf, idx)
        cast_ground(self._raster, self._dist, DIST_SHIFT, np.uint8(MapClass.INTERMEDIATE),
                    float(world_map.origin[0]), float(world_map.origin[1]),
                    float(world_map.resolution), float(world_map.kerb_height), ox, oy, ux, uy,
                    self.slope, mount, h_max, best, surf, idx)
        return self._measure(best, surf, idx, rng, (boxes, ox, oy, ux, uy))

    def _measure(self, best: np.ndarray, surf: np.ndarray, idx: np.ndarray,
                 rng: np.random.Generator, geometry: tuple) -> Cloud:
        c = self.config
        n = _count_returns(best)  # returns before noise, column-major
        # the sweep's whole use of ``rng``: stream keys of counter-based draws (draws.py:
        # NumPy's distributions; both noises from one word a beam, the dropout by its
        # geometric gaps; the third for fading), drawn whether used or not, so that the
        # caller's generator advances as it always did
        k_noise, k_drop, k_fade = stream_keys(rng, 3)
        # the draws' one-word step alone (a loop that pipelines); the point pass scales
        # them and draws the ~1 % rejected ones (beam_normal_pair's values, two passes fewer)
        noisy = c["range_noise"] > 0 or c["intensity_noise"] > 0
        noise, inoise = beam_normal_words(k_noise, n if noisy else 0)
        keep = beam_dropout(k_drop, n, float(c["dropout"]))
        if c["fade_range"] > 0:
            boxes, ox, oy, ux, uy = geometry
            fade_returns(keep, k_fade, best, surf, idx, boxes, AGENT, float(REFLECTANCE[AGENT]),
                         ox, oy, ux, uy, self.slope, self._sec_el, float(c["fade_range"]),
                         float(c["fade_sigma"]))
        pts = np.empty((n, 4), np.float32)
        out_ch = np.empty(n, np.int16)
        out_col = np.empty(n, np.int32)
        out_s = np.empty(n, np.uint8)
        out_i = np.empty(n, np.int32)
        m = _points(best, noisy, k_noise, float(c["range_noise"]), float(c["intensity_noise"]),
                    noise, inoise, keep, surf, idx, self._cos_az, self._sin_az, self._cos_el,
                    self._sin_el, self._sec_el, self._albedo, float(c["min_range"]),
                    float(c["max_range"]), pts, out_ch, out_col, out_s, out_i)
        return Cloud(pts[:m], out_ch[:m], out_col[:m], out_s[:m], out_i[:m], self.mount.copy(),
                     c, best.shape)


@numba.njit(cache=True)
def _count_returns(best):  # pragma: no cover - numba
    n = 0
    for j in range(best.shape[0]):
        for c in range(best.shape[1]):
            if best[j, c] < np.inf:
                n += 1
    return n


@numba.njit(cache=True)
def _points(best, noisy, key, scale_r, scale_i, noise, inoise, keep, surf, idx, cos_az, sin_az,
            cos_el, sin_el, sec_el, albedo, min_range, max_range, pts, out_ch, out_col, out_s,
            out_i):  # pragma: no cover - numba
    """Returns (finite ``best``, column-major) -> noisy Velodyne points and reflectance
    (``albedo[surface, channel]``, 25 % less at 100 m and beyond), written compacted;
    returns how many are kept. The noises of return ``k`` are
    :func:`~dstenv.sensing.draws.beam_normal_pair`'s ``k``-th of stream ``key`` times
    ``scale_r`` / ``scale_i`` (``noise``, ``inoise``: the one-word step, NaN where the
    rest is drawn here; zero when not ``noisy``). Products, not divisions: the loop is
    the sweep's largest."""
    m = 0
    k = -1
    for j in range(best.shape[0]):
        for c in range(best.shape[1]):
            if not best[j, c] < np.inf:
                continue
            k += 1
            if not keep[k]:
                continue
            nr = 0.0
            ni = 0.0
            if noisy:
                nr = noise[k]
                if not nr == nr:
                    nr = beam_normal_rest(key, k, 0)
                nr = 0.0 + scale_r * nr
            r = best[j, c] * sec_el[c] + nr
            if r > max_range or r < min_range:
                continue
            if noisy:
                ni = inoise[k]
                if not ni == ni:
                    ni = beam_normal_rest(key, k, 1)
                ni = 0.0 + scale_i * ni
            ce = cos_el[c] * r
            pts[m, 0] = ce * cos_az[j]
            pts[m, 1] = ce * sin_az[j]
            pts[m, 2] = r * sin_el[c]
            s = surf[j, c]
            v = albedo[s, c] * (1.0 - min(r * 0.0025, 0.25)) + ni
            pts[m, 3] = min(max(v, 0.0), 1.0)
            out_ch[m] = c
            out_col[m] = j
            out_s[m] = s
            out_i[m] = idx[j, c]
            m += 1
    return m


@numba.njit(cache=True)
def _column_poses(pose, speed, yaw_rate, tau, azimuth, mount):  # pragma: no cover - numba
    """Sensor origin ``(ox, oy)``, world azimuth and direction ``(ux, uy)`` of every column
    (``(J,) float64`` each), from the ego ``pose`` at the reference time moving at
    ``speed`` and ``yaw_rate``, column ``j`` firing at ``tau[j]``: one loop (was a dozen
    NumPy calls on 2048 values; the same operations in the same order, the same bits)."""
    n = tau.shape[0]
    ox = np.empty(n)
    oy = np.empty(n)
    world_az = np.empty(n)
    ux = np.empty(n)
    uy = np.empty(n)
    c0 = math.cos(pose[2])
    s0 = math.sin(pose[2])
    turning = abs(yaw_rate) > 1e-9
    steady = yaw_rate == 0.0  # then yaw is pose[2] in every column: its cos and sin once
    for j in range(n):
        yaw = pose[2] + yaw_rate * tau[j]
        if turning:  # the arc integrated exactly
            ex = (math.sin(yaw) - s0) / yaw_rate
            ey = (c0 - math.cos(yaw)) / yaw_rate
        else:
            ex = c0 * tau[j]
            ey = s0 * tau[j]
        cy = c0 if steady else math.cos(yaw)
        sy = s0 if steady else math.sin(yaw)
        ox[j] = pose[0] + speed * ex + cy * mount[0] - sy * mount[1]
        oy[j] = pose[1] + speed * ey + sy * mount[0] + cy * mount[1]
        a = yaw + azimuth[j]
        world_az[j] = a
        ux[j] = math.cos(a)
        uy[j] = math.sin(a)
    return ox, oy, world_az, ux, uy
