"""Array types shared by the simulator and the sensing code (no behaviour here).

All coordinates are in the world frame of :mod:`dstenv.grid` (metres, x east,
y north, yaw counter-clockwise from +x).

Heights (the occluder contract used by the 2-D and 3-D LIDARs), all in metres above
the road surface, which is the plane ``z = 0`` (the world is flat: no slope):

* ground: road, building and unmapped cells are at ``z = 0``;
  :attr:`MapClass.INTERMEDIATE` cells (sidewalks, verges, squares) are raised by the
  kerb, ``WorldMap.kerb_height`` (``world.map.kerb_height``, default 0.12 m).
  :meth:`WorldMap.ground_height` evaluates this at any points.
* buildings: ``WorldMap.building_heights[i]`` is the roof height of the prism over
  ``WorldMap.buildings[i]`` (6-30 m in generated cities; OSM ``height`` /
  ``building:levels`` tags when present).
* agents: ``Agents.height`` is the body height (box from ``z = 0``): car ~1.5, van
  2.2-2.6, truck 3-3.5, pedestrian ~1.7, cyclist ~1.7.
* static clutter (absent from the map): ``WorldMap.obstacles``, oriented boxes from
  ``z_min`` to ``z_max``. A tree is two entries, a thin trunk (0 to ~2.5 m) and a wide
  crown (~2 to 8 m). The 2-D LIDAR scans the horizontal plane at
  ``lidar.plane_height`` (default 0.5 m): an obstacle occludes it only when
  ``z_min <= plane_height <= z_max``, so a crown does not, its trunk does.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any

import numpy as np

__all__ = [
    "MapClass",
    "AgentKind",
    "ObstacleKind",
    "WorldMap",
    "Agents",
    "Obstacles",
    "AGENT_HEIGHT",
    "DEFAULT_BUILDING_HEIGHT",
    "DEFAULT_KERB_HEIGHT",
]

#: Height of a building whose source gives none (hand-built maps, highway-env) [m].
DEFAULT_BUILDING_HEIGHT: float = 10.0
#: Default kerb height of :attr:`MapClass.INTERMEDIATE` cells above the road [m].
DEFAULT_KERB_HEIGHT: float = 0.12


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


#: Body height per :class:`AgentKind` when a creator gives none [m] (car, cyclist,
#: pedestrian); vans and trucks are cars with a larger height set by the spawner.
AGENT_HEIGHT: dict[int, float] = {AgentKind.CAR: 1.5, AgentKind.CYCLIST: 1.7,
                                  AgentKind.PEDESTRIAN: 1.7}


class ObstacleKind(IntEnum):
    """What a piece of static street clutter is (all of it ``non_navigable``)."""

    POLE = 0  # street light / utility pole
    SIGN = 1  # sign post with its panel
    TREE_TRUNK = 2
    TREE_CROWN = 3  # the foliage above a trunk (does not reach the 2-D scan plane)
    HEDGE = 4
    FENCE = 5
    BIN = 6  # waste bin / container
    BOLLARD = 7
    BICYCLE = 8  # parked bicycle
    SHELTER = 9  # bus shelter
    OTHER = 10


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
        building_heights: ``(B,) float64`` roof height of each building [m]; left
            ``None`` it becomes :data:`DEFAULT_BUILDING_HEIGHT` for every building.
        obstacles: static street clutter absent from the map (:class:`Obstacles`);
            ``None`` becomes :meth:`Obstacles.empty`.
        kerb_height: height of :attr:`MapClass.INTERMEDIATE` ground above the road [m].
    """

    raster: np.ndarray
    origin: tuple[float, float]
    resolution: float
    buildings: list[np.ndarray] = field(default_factory=list)
    lanes: Any = None
    meta: dict[str, Any] = field(default_factory=dict)
    building_heights: np.ndarray | None = None
    obstacles: "Obstacles | None" = None
    kerb_height: float = DEFAULT_KERB_HEIGHT

    def __post_init__(self) -> None:
        if self.building_heights is None:
            self.building_heights = np.full(len(self.buildings), DEFAULT_BUILDING_HEIGHT)
        self.building_heights = np.asarray(self.building_heights, dtype=np.float64)
        if self.building_heights.shape != (len(self.buildings),):
            raise ValueError(
                f"WorldMap.building_heights: shape {self.building_heights.shape} does not "
                f"match {len(self.buildings)} buildings"
            )
        if self.obstacles is None:
            self.obstacles = Obstacles.empty()

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """``(x_min, x_max, y_min, y_max)`` [m] covered by the raster."""
        h, w = self.raster.shape
        x0, y0 = self.origin
        return (x0, x0 + w * self.resolution, y0, y0 + h * self.resolution)

    def ground_height(self, xy: np.ndarray) -> np.ndarray:
        """Ground height at world points: ``xy (..., 2)`` -> ``(...) float64`` [m].

        ``kerb_height`` on :attr:`MapClass.INTERMEDIATE` cells, 0 elsewhere (also
        outside the raster).
        """
        xy = np.asarray(xy, dtype=np.float64)
        h, w = self.raster.shape
        c = np.floor((xy[..., 0] - self.origin[0]) / self.resolution).astype(np.int64)
        r = np.floor((xy[..., 1] - self.origin[1]) / self.resolution).astype(np.int64)
        inside = (r >= 0) & (r < h) & (c >= 0) & (c < w)
        cls = np.zeros(r.shape, np.uint8)
        cls[inside] = self.raster[r[inside], c[inside]]
        return np.where(cls == MapClass.INTERMEDIATE, self.kerb_height, 0.0)


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
        height: ``(N,) float64`` body height [m] (a box from the ground up); left
            ``None`` it is :data:`AGENT_HEIGHT` of each agent's kind.
    """

    xy: np.ndarray
    yaw: np.ndarray
    speed: np.ndarray
    length: np.ndarray
    width: np.ndarray
    kind: np.ndarray
    parked: np.ndarray
    height: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.height is None:
            table = np.array([AGENT_HEIGHT[k] for k in sorted(AGENT_HEIGHT)])
            self.height = table[np.asarray(self.kind, dtype=np.int64)]

    def __len__(self) -> int:
        return int(self.yaw.shape[0])

    @classmethod
    def empty(cls) -> "Agents":
        """No agents."""
        z = np.zeros(0, dtype=np.float64)
        return cls(np.zeros((0, 2)), z, z.copy(), z.copy(), z.copy(),
                   np.zeros(0, np.uint8), np.zeros(0, bool), z.copy())

    def corners(self) -> np.ndarray:
        """Footprint corners: ``(N, 4, 2) float64`` world coordinates, counter-clockwise."""
        return _box_corners(self.xy, self.yaw, self.length, self.width)


def _box_corners(xy: np.ndarray, yaw: np.ndarray, length: np.ndarray,
                 width: np.ndarray) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    hl, hw = length / 2, width / 2
    local = np.stack(
        [np.stack([hl, hw], -1), np.stack([-hl, hw], -1),
         np.stack([-hl, -hw], -1), np.stack([hl, -hw], -1)], axis=1
    )  # (N, 4, 2)
    rot = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], axis=1)  # (N, 2, 2)
    return np.einsum("nij,nkj->nki", rot, local) + xy[:, None, :]


@dataclass
class Obstacles:
    """Static street clutter as K oriented boxes (absent from the map, ``non_navigable``).

    Attributes:
        xy: ``(K, 2) float64`` centre of the footprint [m].
        yaw: ``(K,) float64`` heading of the ``length`` side [rad].
        length: ``(K,) float64`` footprint length [m].
        width: ``(K,) float64`` footprint width [m].
        z_min: ``(K,) float64`` bottom of the box above the road surface [m].
        z_max: ``(K,) float64`` top of the box [m].
        kind: ``(K,) uint8`` :class:`ObstacleKind`.
    """

    xy: np.ndarray
    yaw: np.ndarray
    length: np.ndarray
    width: np.ndarray
    z_min: np.ndarray
    z_max: np.ndarray
    kind: np.ndarray

    def __len__(self) -> int:
        return int(self.yaw.shape[0])

    @classmethod
    def empty(cls) -> "Obstacles":
        """No obstacles."""
        z = np.zeros(0, dtype=np.float64)
        return cls(np.zeros((0, 2)), z, z.copy(), z.copy(), z.copy(), z.copy(),
                   np.zeros(0, np.uint8))

    def corners(self) -> np.ndarray:
        """Footprint corners: ``(K, 4, 2) float64`` world coordinates, counter-clockwise."""
        return _box_corners(self.xy, self.yaw, self.length, self.width)

    def at_height(self, z: float) -> np.ndarray:
        """``(K,) bool``: the boxes that the horizontal plane at height ``z`` [m] cuts."""
        return (self.z_min <= z) & (z <= self.z_max)
