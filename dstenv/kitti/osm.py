"""GIS grids for KITTI from an OpenStreetMap file, aligned by the OXTS poses.

:func:`dstenv.sim.osm.load_osm` rasterises the map in its own metric frame
(Mercator with ``meta["mercator_scale"]``, minus ``meta["mercator_offset"]``, the
Mercator position of ``meta["latlon_origin"]``). A
KITTI world pose (Mercator around the first Velodyne position, scale of the first
latitude) is taken back to latitude/longitude and forward into the map's frame;
both frames are north-up, so the heading carries over unchanged.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from dstenv.grid import GridSpec
from dstenv.kitti.poses import Trajectory, latlon_to_mercator
from dstenv.kitti.readers import KittiError
from dstenv.sim.types import WorldMap

__all__ = ["MapAlignment", "map_lookup"]


class MapAlignment:
    """KITTI world frame -> the metric frame of a loaded OSM map.

    Args:
        world_map: from :func:`dstenv.sim.osm.load_osm` (its ``meta`` must hold
            ``latlon_origin`` and ``mercator_scale``).
        trajectory: the sequence's poses.

    Raises:
        KittiError: the map lacks the georeference.
    """

    def __init__(self, world_map: WorldMap, trajectory: Trajectory) -> None:
        meta = world_map.meta or {}
        try:
            lat0, lon0 = (float(v) for v in meta["latlon_origin"])
            self.scale = float(meta["mercator_scale"])
        except (KeyError, TypeError, ValueError):
            raise KittiError(
                "OSM map has no georeference (meta latlon_origin, mercator_scale)"
            ) from None
        if "mercator_offset" in meta:
            self.origin = np.asarray(meta["mercator_offset"], dtype=np.float64).reshape(2)
        else:
            self.origin = np.array(latlon_to_mercator(lat0, lon0, self.scale), dtype=np.float64)
        self.trajectory = trajectory
        self.map = world_map

    def to_map(self, xy: np.ndarray) -> np.ndarray:
        """KITTI world points ``(..., 2)`` [m] -> map frame ``(..., 2)`` [m]."""
        lat, lon = self.trajectory.world_to_latlon(xy)
        mx, my = latlon_to_mercator(lat, lon, self.scale)
        return np.stack([mx - self.origin[0], my - self.origin[1]], axis=-1)

    def pose(self, pose: np.ndarray) -> np.ndarray:
        """A KITTI world pose ``(3,)`` in the map frame (heading unchanged)."""
        x, y = self.to_map(np.asarray(pose[:2], dtype=np.float64))
        return np.array([x, y, float(pose[2])])

    def coverage(self) -> float:
        """Share of the sequence's poses that lie on the map raster."""
        xy = self.to_map(self.trajectory.poses[:, :2])
        x0, x1, y0, y1 = self.map.bounds
        inside = (xy[:, 0] >= x0) & (xy[:, 0] < x1) & (xy[:, 1] >= y0) & (xy[:, 1] < y1)
        return float(inside.mean())


def map_lookup(
    osm_path: str | Path, trajectory: Trajectory
) -> tuple[Callable[[np.ndarray, GridSpec], np.ndarray], str]:
    """Load an ``.osm`` file and return ``(gis_fn, note)`` for the converter.

    ``gis_fn(pose, spec) -> (H, W) uint8`` cuts the GIS grid at a KITTI world pose.

    Raises:
        KittiError: unreadable or invalid map (one line naming the file), or a map
            that does not cover any pose of the drive.
    """
    from dstenv.sensing import gis_grid
    from dstenv.sim.osm import load_osm

    path = Path(osm_path)
    try:
        world_map = load_osm(path)
    except KittiError:
        raise
    except (ValueError, OSError) as exc:
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise KittiError(msg if str(path) in msg else f"{path}: {msg}") from None
    align = MapAlignment(world_map, trajectory)
    cover = align.coverage()
    if cover == 0.0:
        lat, lon = trajectory.latlon0
        x0, x1, y0, y1 = world_map.bounds
        raise KittiError(
            f"{path}: the map does not cover the drive (first pose at lat {lat:.5f}, "
            f"lon {lon:.5f}; the map spans {x1 - x0:.0f} x {y1 - y0:.0f} m elsewhere)"
        )

    def gis_fn(pose: np.ndarray, spec: GridSpec) -> np.ndarray:
        return gis_grid(world_map, align.pose(pose), spec)

    note = f"map: {path} (aligned by OXTS; {100 * cover:.0f}% of the poses on the map)"
    return gis_fn, note
