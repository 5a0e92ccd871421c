"""KITTI tracking (+ OpenStreetMap) -> the same perception grids, labels and shards.

Flow: :mod:`~dstenv.kitti.readers` (Velodyne, labels, calibration, OXTS) ->
:mod:`~dstenv.kitti.poses` (devkit Mercator poses) and
:mod:`~dstenv.kitti.objects` (boxes in the Velodyne frame, moving rules) ->
:mod:`dstenv.sensing.cloud` (RANSAC plane + polar walk, sensor grid by ray casting) ->
:mod:`~dstenv.kitti.grids` (label grid) and
:mod:`~dstenv.kitti.osm` (GIS grid from an ``.osm`` file) ->
:mod:`~dstenv.kitti.sequence` (the DST filter, :class:`dstenv.frame.Frame` objects) ->
``dstenv kitti convert`` (:mod:`~dstenv.kitti.cli`) writes shards like ``dstenv generate``.

Names are imported lazily, so ``import dstenv.kitti`` imports neither scipy nor numba.
"""

from dstenv._lazy import lazy_attributes

_WHERE = {
    "KittiError": "readers", "OBJECT_TYPES": "readers", "Labels": "readers",
    "Calibration": "readers", "read_velodyne": "readers", "read_labels": "readers",
    "read_calib": "readers", "read_oxts": "readers",
    "Trajectory": "poses", "oxts_to_trajectory": "poses",
    "Boxes": "objects", "boxes_in_velodyne": "objects", "moving_flags": "objects",
    "default_config": "sequence", "kitti_config": "sequence", "KittiSequence": "sequence",
    "convert_sequence": "sequence",
}
__all__ = sorted(_WHERE)
__getattr__, __dir__ = lazy_attributes(__name__, _WHERE)
