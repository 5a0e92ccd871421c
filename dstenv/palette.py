"""The colours of every figure dstenv draws: one palette, so a class looks the same
in the env render, the benchmark report, KITTI frames and scene plots.

Arrays are ``uint8`` RGB; :func:`as_float` gives matplotlib's ``[0, 1]`` floats.
"""

from __future__ import annotations

import numpy as np

__all__ = ["CLASS_RGB", "IGNORE_RGB", "SENSOR_RGB", "SURFACE_RGB", "MAPCLASS_RGB",
           "CLUTTER_RGB", "as_float", "label_image"]

#: ``(5, 3) uint8`` colour of each class in ``dstenv.dst.CLASSES`` order.
CLASS_RGB: np.ndarray = np.array(
    [
        [205, 205, 205],  # navigable: light grey road
        [105, 160, 90],  # non_navigable: green verge / sidewalk
        [70, 95, 170],  # building: slate blue
        [245, 170, 30],  # static: orange
        [225, 35, 35],  # moving: red
    ],
    dtype=np.uint8,
)
#: cells labelled ``IGNORE_INDEX`` (outside the camera, DontCare): near-white
IGNORE_RGB: np.ndarray = np.array([238, 238, 238], np.uint8)
#: sensor grid codes: unknown (mid grey), free (white), occupied (black)
SENSOR_RGB: np.ndarray = np.array([[140, 140, 140], [255, 255, 255], [0, 0, 0]], np.uint8)
#: :class:`dstenv.sim.raster.Surface` codes: yard, building, road, sidewalk, parking,
#: crosswalk, verge (roundabout islands, medians)
SURFACE_RGB: np.ndarray = np.array(
    [[204, 219, 189], [107, 102, 115], [140, 140, 145], [219, 214, 204], [178, 178, 168],
     [237, 237, 237], [150, 190, 120]], np.uint8)
#: :class:`dstenv.sim.types.MapClass` codes: none, building, road, intermediate
MAPCLASS_RGB: np.ndarray = np.array(
    [[255, 255, 255], [107, 102, 115], [140, 140, 145], [219, 214, 204]], np.uint8)


#: street clutter in scene plots: standing on the ground (dark olive), tree crowns
#: (green, drawn translucent)
CLUTTER_RGB = np.array([[85, 107, 47], [60, 141, 47]], np.uint8)


def as_float(rgb: np.ndarray) -> np.ndarray:
    """``uint8`` colours -> ``float64`` in ``[0, 1]`` (matplotlib)."""
    return np.asarray(rgb, np.float64) / 255.0


def label_image(labels: np.ndarray, ignore_index: int = 255) -> np.ndarray:
    """``(H, W)`` class labels -> ``(H, W, 3) uint8``; ignored cells in :data:`IGNORE_RGB`."""
    ign = labels == ignore_index
    out = CLASS_RGB[np.where(ign, 0, np.clip(labels, 0, len(CLASS_RGB) - 1))]
    out[ign] = IGNORE_RGB
    return out
