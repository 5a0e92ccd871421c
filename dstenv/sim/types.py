"""Array types shared by the simulator and the sensing code (no behaviour here).

All coordinates are in the world frame of :mod:`dstenv.grid` (metres, x east,
y north, yaw counter-clockwise from +x).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any

import numpy as np

__all__ = ["MapClass", "AgentKind", "WorldMap", "Agents"]


class MapClass(IntEnum):
    """Codes of a map raster and of a GIS grid (as read by ``dstenv.dst.map_masses``)."""

    NONE = 0  # no map information
    BUILDING = 1
    ROAD = 2
    INTERMEDIATE = 3  # sidewalk, verge, parking strip, square: neither road nor building


class AgentKind(IntEnum):
    """What an agent is; its footprint and behaviour follow from it."""

    CAR = 0
    CYCLIST = 1
    PEDESTRIAN = 2


@dataclass
class WorldMap:
    """A static map: a class raster for fast lookups plus vector geometry.

    Attributes:
        raster: ``(Hm, Wm) uint8`` :class:`MapClass` codes. Row ``r``, column ``c``
            is the square ``x in [x0 + c*res, x0 + (c+1)*res)``,
            ``y in [y0 + r*res, y0 + (r+1)*res)`` (row index grows with y).
        origin: ``(x0, y0)`` world coordinates of the raster corner [m].
        resolution: raster cell size [m].
        buildings: building footprints, each ``(K, 2) float64`` polygon (world).
        lanes: the simulator's lane network (opaque to sensing code).
        meta: free-form provenance (generator seed, OSM file, lat/lon origin...).
    """

    raster: np.ndarray
    origin: tuple[float, float]
    resolution: float
    buildings: list[np.ndarray] = field(default_factory=list)
    lanes: Any = None
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """``(x_min, x_max, y_min, y_max)`` [m] covered by the raster."""
        h, w = self.raster.shape
        x0, y0 = self.origin
        return (x0, x0 + w * self.resolution, y0, y0 + h * self.resolution)


@dataclass
class Agents:
    """Structure-of-arrays state of N agents (the ego is not among them).

    Attributes:
        xy: ``(N, 2) float64`` centre of the footprint [m].
        yaw: ``(N,) float64`` heading [rad].
        speed: ``(N,) float64`` speed magnitude [m/s].
        length: ``(N,) float64`` footprint length along the heading [m].
        width: ``(N,) float64`` footprint width [m].
        kind: ``(N,) uint8`` :class:`AgentKind`.
        parked: ``(N,) bool`` parked (never moves in this episode).
    """

    xy: np.ndarray
    yaw: np.ndarray
    speed: np.ndarray
    length: np.ndarray
    width: np.ndarray
    kind: np.ndarray
    parked: np.ndarray

    def __len__(self) -> int:
        return int(self.yaw.shape[0])

    @classmethod
    def empty(cls) -> "Agents":
        """No agents."""
        z = np.zeros(0, dtype=np.float64)
        return cls(np.zeros((0, 2)), z, z.copy(), z.copy(), z.copy(),
                   np.zeros(0, np.uint8), np.zeros(0, bool))

    def corners(self) -> np.ndarray:
        """Footprint corners: ``(N, 4, 2) float64`` world coordinates, counter-clockwise."""
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        hl, hw = self.length / 2, self.width / 2
        local = np.stack(
            [np.stack([hl, hw], -1), np.stack([-hl, hw], -1),
             np.stack([-hl, -hw], -1), np.stack([hl, -hw], -1)], axis=1
        )  # (N, 4, 2)
        rot = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], axis=1)  # (N, 2, 2)
        return np.einsum("nij,nkj->nki", rot, local) + self.xy[:, None, :]
