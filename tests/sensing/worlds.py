"""Hand-built worlds for the sensing tests: rectangular buildings and explicit agents."""

from __future__ import annotations

import numpy as np

from dstenv.sim.types import AgentKind, Agents, MapClass, WorldMap


def rect_map(
    rects: list[tuple[float, float, float, float]],
    extent: tuple[float, float, float, float] = (-40.0, 40.0, -40.0, 40.0),
    resolution: float = 0.1,
    fill: int = MapClass.ROAD,
    polygons: bool = True,
) -> WorldMap:
    """A map of ``fill`` with axis-aligned buildings ``(x_lo, x_hi, y_lo, y_hi)`` [m].

    Raster cells whose centre lies inside a rectangle are BUILDING (the simulator's
    rule); ``polygons=False`` leaves ``WorldMap.buildings`` empty (raster only).
    """
    x0, x1, y0, y1 = extent
    w = int(round((x1 - x0) / resolution))
    h = int(round((y1 - y0) / resolution))
    raster = np.full((h, w), fill, dtype=np.uint8)
    xc = x0 + (np.arange(w) + 0.5) * resolution
    yc = y0 + (np.arange(h) + 0.5) * resolution
    polys = []
    for xl, xh, yl, yh in rects:
        inside = ((yc >= yl) & (yc <= yh))[:, None] & ((xc >= xl) & (xc <= xh))[None, :]
        raster[inside] = MapClass.BUILDING
        polys.append(np.array([[xl, yl], [xh, yl], [xh, yh], [xl, yh]], dtype=np.float64))
    return WorldMap(raster, (x0, y0), resolution, polys if polygons else [])


def agents(*boxes: tuple[float, float, float, float, float, float]) -> Agents:
    """Agents from ``(x, y, yaw, length, width, speed)`` tuples (all cars, none parked)."""
    if not boxes:
        return Agents.empty()
    a = np.array(boxes, dtype=np.float64).reshape(-1, 6)
    n = len(a)
    return Agents(a[:, :2].copy(), a[:, 2].copy(), a[:, 5].copy(), a[:, 3].copy(), a[:, 4].copy(),
                  np.full(n, AgentKind.CAR, np.uint8), np.zeros(n, bool))
