"""Sensing: a 2-D LIDAR with occlusion, sensor / GIS grids and exact labels (no gymnasium).

Flow: :meth:`Lidar.sweep` (world -> per-beam ranges) -> :func:`sensor_grid`
(ranges -> free / occupied / unknown cells) ; :func:`gis_grid` (map -> map classes
in the ego frame) ; :func:`label_grid` (map + agents -> ground truth) and
:func:`visible_mask` (sensor grid -> observed cells).
"""

from dstenv.sensing.config import default_config
from dstenv.sensing.gis import MapError, gis_grid, lookup_map
from dstenv.sensing.labels import MAP_TO_CLASS, label_grid, visible_mask
from dstenv.sensing.lidar import HIT_BUILDING, HIT_NONE, Lidar, Sweep
from dstenv.sensing.raycast import sensor_grid

__all__ = [
    "default_config",
    "Lidar",
    "Sweep",
    "HIT_NONE",
    "HIT_BUILDING",
    "sensor_grid",
    "gis_grid",
    "lookup_map",
    "MapError",
    "label_grid",
    "visible_mask",
    "MAP_TO_CLASS",
]
