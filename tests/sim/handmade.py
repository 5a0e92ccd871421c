"""A hand-built map for exact tests: one 4-way junction with 60 m arms (1 or more lanes
per direction)."""

from __future__ import annotations

import numpy as np

from dstenv.sim.lanes import Control, LaneKind, LaneNetwork, NetworkBuilder, Turn
from dstenv.sim.raster import fill_rect
from dstenv.sim.roads import RoadEdge, add_road_lanes
from dstenv.sim.types import MapClass, WorldMap

ARM = 60.0  # [m] junction centre -> arm end
TRIM = 10.0  # [m] junction centre -> stop line
LW = 3.25  # [m] lane width
RES = 0.2  # [m]
BLOCK = (LW + 4.0, LW + 24.0)  # building square in each quadrant, distance from the axes


def cross_map(control: Control = Control.STOP, lanes: int = 1) -> WorldMap:
    """Junction at (0, 0); arms east, north, west, south with ``lanes`` lanes per
    direction (lane ``k`` from the centre line at ``(k + 0.5) LW``); a building in each
    quadrant."""
    node_xy = np.array([[0, 0], [ARM, 0], [0, ARM], [-ARM, 0], [0, -ARM]], float)
    edges = [RoadEdge(0, k, node_xy[[0, k]], lanes, lanes) for k in range(1, 5)]
    builder = NetworkBuilder()
    add_road_lanes(builder, 5, edges, np.full(5, TRIM), LW)
    controls = np.array([control] + [Control.NONE] * 4, np.uint8)
    net = builder.build(node_xy, controls, np.zeros(5), LW)
    lo = -ARM - 10.0
    n = int(round(2 * (ARM + 10.0) / RES))
    raster = np.full((n, n), MapClass.INTERMEDIATE, np.uint8)
    org = (lo, lo)
    half = LW * lanes
    fill_rect(raster, -ARM - 5, ARM + 5, -half, half, org, RES, MapClass.ROAD)
    fill_rect(raster, -half, half, -ARM - 5, ARM + 5, org, RES, MapClass.ROAD)
    buildings = []
    a, b = BLOCK[0] + half - LW, BLOCK[1]
    for sx in (1, -1):
        for sy in (1, -1):
            xs, ys = sorted((sx * a, sx * b)), sorted((sy * a, sy * b))
            fill_rect(raster, *xs, *ys, org, RES, MapClass.BUILDING)
            buildings.append(np.array([[xs[0], ys[0]], [xs[1], ys[0]], [xs[1], ys[1]],
                                       [xs[0], ys[1]]]))
    return WorldMap(raster=raster, origin=org, resolution=RES, buildings=buildings, lanes=net)


def lane_ending_near(net: LaneNetwork, x: float, y: float) -> int:
    """The road lane whose last point is closest to ``(x, y)``."""
    road = np.flatnonzero(net.kind == LaneKind.ROAD)
    ends = np.array([net.polyline(k)[-1] for k in road])
    return int(road[np.argmin(np.hypot(*(ends - [x, y]).T))])


def lane_starting_near(net: LaneNetwork, x: float, y: float) -> int:
    """The road lane whose first point is closest to ``(x, y)``."""
    road = np.flatnonzero(net.kind == LaneKind.ROAD)
    starts = np.array([net.polyline(k)[0] for k in road])
    return int(road[np.argmin(np.hypot(*(starts - [x, y]).T))])


def straight_connector(net: LaneNetwork, lane: int) -> int:
    """The straight-on connector after ``lane``."""
    return next(int(c) for c in net.successors(lane) if net.turn[c] == Turn.STRAIGHT
                and net.kind[c] == LaneKind.CONNECTOR)
