"""Shared settings of the env tests: small grids keep every test to seconds."""

from __future__ import annotations

from typing import Any


#: A grid just above NatureCNN's 36 x 36 minimum.
SMALL_GRID: dict[str, Any] = {"height": 40, "width": 40, "cell_size": 1.0}

#: Small city: 2 x 2 blocks, light traffic (fast resets), fewer beams.
SMALL_CITY: dict[str, Any] = {
    "grid": SMALL_GRID,
    "lidar": {"beams": 360},
    "world": {"map": {"blocks_x": 2, "blocks_y": 2},
              "traffic": {"cars": 8, "cyclists": 1, "pedestrians": 6}},
}

#: Small highway-env backend: coarse map raster, fewer beams, the plain image grid.
SMALL_HIGHWAY: dict[str, Any] = {
    "source": "highway",
    "observation": {"type": "image"},
    "grid": SMALL_GRID,
    "lidar": {"beams": 360},
    "highway": {"resolution": 0.5},
}

