"""KITTI tracking (+ OpenStreetMap) -> the same perception grids, labels and shards.

Flow: :mod:`~dstenv.kitti.readers` (Velodyne, labels, calibration, OXTS) ->
:mod:`~dstenv.kitti.poses` (devkit Mercator poses) and
:mod:`~dstenv.kitti.objects` (boxes in the Velodyne frame, moving rules) ->
:mod:`dstenv.sensing.cloud` (RANSAC plane + polar walk, sensor grid by ray casting) ->
:mod:`~dstenv.kitti.grids` (label grid) and
:mod:`~dstenv.kitti.osm` (GIS grid from an ``.osm`` file) ->
:mod:`~dstenv.kitti.sequence` (the DST filter, :class:`dstenv.frame.Frame` objects) ->
``dstenv kitti convert`` (:mod:`~dstenv.kitti.cli`) writes shards like ``dstenv generate``.
"""

from dstenv.kitti.objects import Boxes, boxes_in_velodyne, moving_flags
from dstenv.kitti.poses import Trajectory, oxts_to_trajectory
from dstenv.kitti.readers import (
    OBJECT_TYPES,
    Calibration,
    KittiError,
    Labels,
    read_calib,
    read_labels,
    read_oxts,
    read_velodyne,
)
from dstenv.kitti.sequence import KittiSequence, convert_sequence, default_config, kitti_config

__all__ = [
    "KittiError", "OBJECT_TYPES", "Labels", "Calibration",
    "read_velodyne", "read_labels", "read_calib", "read_oxts",
    "Trajectory", "oxts_to_trajectory",
    "Boxes", "boxes_in_velodyne", "moving_flags",
    "default_config", "kitti_config", "KittiSequence", "convert_sequence",
]
