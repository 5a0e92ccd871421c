"""OXTS (GPS/IMU) rows -> metric world poses, following the KITTI devkit.

The devkit projects latitude/longitude with a Mercator projection whose scale is
``cos(lat0)`` of the first frame, builds the IMU attitude as
``R = Rz(yaw) Ry(pitch) Rx(roll)`` (OXTS axes: x forward, y left, z up; yaw 0 =
east, counter-clockwise) and expresses every pose relative to the first one.

Here the world frame is that of :mod:`dstenv.grid` (x east, y north): we keep the
devkit's Mercator coordinates and translate them so that the **Velodyne** of the
first frame sits at the origin, without rotating them, so an OpenStreetMap map
(which is north-up) aligns by a translation only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# The devkit's projection is defined once, next to the OSM loader that shares it.
from dstenv.sim.osm_xml import EARTH_RADIUS, latlon_to_mercator

__all__ = [
    "EARTH_RADIUS",
    "lat_to_scale",
    "latlon_to_mercator",
    "mercator_to_latlon",
    "Trajectory",
    "oxts_to_trajectory",
]


def lat_to_scale(lat: float) -> float:
    """Mercator scale ``cos(lat)`` of the devkit, ``lat`` in degrees."""
    return float(np.cos(np.deg2rad(lat)))


def mercator_to_latlon(
    mx: np.ndarray | float, my: np.ndarray | float, scale: float
) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`latlon_to_mercator`: ``(lat, lon)`` in degrees."""
    k = scale * EARTH_RADIUS
    lon = np.rad2deg(np.asarray(mx, dtype=np.float64) / k)
    lat = 2.0 * np.rad2deg(np.arctan(np.exp(np.asarray(my, dtype=np.float64) / k))) - 90.0
    return lat, lon


def _rotation(roll: np.ndarray, pitch: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """``(N, 3, 3)``: ``Rz(yaw) @ Ry(pitch) @ Rx(roll)``."""
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cy, sy = np.cos(yaw), np.sin(yaw)
    r = np.empty(roll.shape + (3, 3))
    r[..., 0, 0] = cy * cp
    r[..., 0, 1] = cy * sp * sr - sy * cr
    r[..., 0, 2] = cy * sp * cr + sy * sr
    r[..., 1, 0] = sy * cp
    r[..., 1, 1] = sy * sp * sr + cy * cr
    r[..., 1, 2] = sy * sp * cr - cy * sr
    r[..., 2, 0] = -sp
    r[..., 2, 1] = cp * sr
    r[..., 2, 2] = cp * cr
    return r


@dataclass(frozen=True)
class Trajectory:
    """World poses of one sequence.

    Attributes:
        velo: ``(N, 4, 4) float64`` Velodyne -> world (x east, y north, z up).
        poses: ``(N, 3) float64`` planar Velodyne poses ``(x, y, yaw)`` [m, m, rad],
            the ``ego_pose`` of the frames; ``poses[0, :2] == 0``.
        scale: Mercator scale (cos of the first latitude).
        origin: ``(2,) float64`` scaled Mercator coordinates of the world origin [m].
        latlon0: ``(2,) float64`` latitude, longitude of the first frame [deg].
    """

    velo: np.ndarray
    poses: np.ndarray
    scale: float
    origin: np.ndarray
    latlon0: np.ndarray

    def latlon_to_world(self, lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
        """World coordinates ``(..., 2) float64`` [m] of lat/lon in degrees."""
        mx, my = latlon_to_mercator(lat, lon, self.scale)
        return np.stack([mx - self.origin[0], my - self.origin[1]], axis=-1)

    def world_to_latlon(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(lat, lon)`` in degrees of world points ``(..., 2)`` [m]."""
        xy = np.asarray(xy, dtype=np.float64)
        mx, my = xy[..., 0] + self.origin[0], xy[..., 1] + self.origin[1]
        return mercator_to_latlon(mx, my, self.scale)

    def to_world(self, frame: int, points: np.ndarray) -> np.ndarray:
        """Velodyne points ``(P, 3)`` of one frame -> world ``(P, 3) float64``."""
        t = self.velo[frame]
        return np.asarray(points, dtype=np.float64) @ t[:3, :3].T + t[:3, 3]


def oxts_to_trajectory(oxts: np.ndarray, tr_imu_velo: np.ndarray | None = None) -> Trajectory:
    """Convert OXTS rows to Velodyne world poses.

    Args:
        oxts: ``(N, 30) float64`` rows from :func:`dstenv.kitti.readers.read_oxts`.
        tr_imu_velo: ``(4, 4)`` IMU -> Velodyne transform from the calibration;
            ``None`` treats the Velodyne as sitting on the IMU.

    Returns:
        The :class:`Trajectory`, scale from the first frame's latitude (the devkit's
        choice), origin at the first Velodyne position.
    """
    oxts = np.asarray(oxts, dtype=np.float64)
    scale = lat_to_scale(oxts[0, 0])
    mx, my = latlon_to_mercator(oxts[:, 0], oxts[:, 1], scale)
    imu = np.tile(np.eye(4), (len(oxts), 1, 1))
    imu[:, :3, :3] = _rotation(oxts[:, 3], oxts[:, 4], oxts[:, 5])
    imu[:, 0, 3], imu[:, 1, 3], imu[:, 2, 3] = mx, my, oxts[:, 2]
    velo_to_imu = np.eye(4) if tr_imu_velo is None else np.linalg.inv(tr_imu_velo)
    velo = imu @ velo_to_imu
    origin = velo[0, :2, 3].copy()
    velo[:, :2, 3] -= origin
    poses = np.stack(
        [velo[:, 0, 3], velo[:, 1, 3], np.arctan2(velo[:, 1, 0], velo[:, 0, 0])], axis=1
    )
    return Trajectory(
        velo=velo, poses=poses, scale=scale, origin=origin, latlon0=oxts[0, :2].copy()
    )
