"""Labelled objects: camera-frame boxes -> Velodyne-frame footprints, and motion.

A label row gives the box's bottom-face centre and ``rotation_y`` in the
rectified camera frame (x right, y down, z forward). We map the centre to the
Velodyne frame with the inverse of ``R_rect @ Tr_velo_cam`` and turn the
object's heading (its local +x axis, ``(cos ry, 0, -sin ry)`` in the camera)
with the same rotation, so a slightly tilted calibration is honoured.

Motion rules (per object and frame; see :func:`moving_flags`):

* ``"paper"``: moving if its world position moved more than ``threshold``
  (10 cm) since the previous labelled frame of its track (per frame interval:
  a track unlabelled for k - 1 frames may move k x 10 cm). Pose noise of the OXTS
  (the sample's ego speed jitters by about 1 m/s frame to frame) makes parked cars
  jump by 5-10 cm, so this rule flickers.
* ``"smoothed"``: a least-squares line through the track's world positions over
  ``window`` frames either side gives a speed; moving if that speed exceeds
  ``threshold`` per frame interval (10 cm at 10 Hz = 1 m/s).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dstenv.kitti.poses import Trajectory
from dstenv.kitti.readers import Calibration, Labels

__all__ = ["Boxes", "boxes_in_velodyne", "world_centres", "moving_flags", "MOVING_RULES"]

MOVING_RULES: tuple[str, ...] = ("paper", "smoothed")


@dataclass
class Boxes:
    """Object footprints in the Velodyne frame (x forward, y left, z up).

    Attributes:
        frame: ``(K,) int64`` frame index.
        track: ``(K,) int64`` track id.
        type: ``(K,) int64`` index into :data:`dstenv.kitti.readers.OBJECT_TYPES`.
        centre: ``(K, 3) float64`` box centre (half-way up) [m].
        length: ``(K,) float64`` extent along the heading [m].
        width: ``(K,) float64`` extent across the heading [m].
        height: ``(K,) float64`` [m].
        yaw: ``(K,) float64`` heading, counter-clockwise from Velodyne +x [rad].
    """

    frame: np.ndarray
    track: np.ndarray
    type: np.ndarray
    centre: np.ndarray
    length: np.ndarray
    width: np.ndarray
    height: np.ndarray
    yaw: np.ndarray

    def __len__(self) -> int:
        return int(self.frame.shape[0])

    def select(self, mask: np.ndarray) -> Boxes:
        """The boxes where ``mask`` (``(K,) bool``) is true."""
        return Boxes(*(getattr(self, f)[mask] for f in self.__dataclass_fields__))

    def corners(self) -> np.ndarray:
        """Footprint corners ``(K, 4, 2) float64`` in the Velodyne x-y plane, CCW."""
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        hl, hw = self.length / 2, self.width / 2
        lx = np.stack([hl, -hl, -hl, hl], axis=1)
        ly = np.stack([hw, hw, -hw, -hw], axis=1)
        x = self.centre[:, :1] + c[:, None] * lx - s[:, None] * ly
        y = self.centre[:, 1:2] + s[:, None] * lx + c[:, None] * ly
        return np.stack([x, y], axis=-1)


def boxes_in_velodyne(labels: Labels, calib: Calibration) -> Boxes:
    """Convert the non-``DontCare`` label rows to Velodyne-frame boxes.

    Args:
        labels: rows from :func:`dstenv.kitti.readers.read_labels` (``DontCare``
            rows are dropped here).
        calib: the sequence calibration.

    Returns:
        :class:`Boxes`, one per remaining row, in the rows' order.
    """
    obj = labels.select(~labels.is_dontcare)
    height, width, length = obj.hwl[:, 0], obj.hwl[:, 1], obj.hwl[:, 2]
    centre_cam = obj.location.copy()
    centre_cam[:, 1] -= height / 2  # camera y points down: the centre is above the bottom face
    t = calib.rect_to_velo
    centre = centre_cam @ t[:3, :3].T + t[:3, 3]
    ry = obj.rotation_y
    heading_cam = np.stack([np.cos(ry), np.zeros_like(ry), -np.sin(ry)], axis=1)
    heading = heading_cam @ t[:3, :3].T
    return Boxes(
        frame=obj.frame, track=obj.track, type=obj.type, centre=centre,
        length=length.copy(), width=width.copy(), height=height.copy(),
        yaw=np.arctan2(heading[:, 1], heading[:, 0]),
    )


def world_centres(boxes: Boxes, trajectory: Trajectory) -> np.ndarray:
    """World positions ``(K, 2) float64`` [m] of the box centres.

    Raises:
        IndexError: if a box's frame has no pose (checked by the caller).
    """
    out = np.empty((len(boxes), 2))
    for f in np.unique(boxes.frame):
        sel = boxes.frame == f
        out[sel] = trajectory.to_world(int(f), boxes.centre[sel])[:, :2]
    return out


def moving_flags(
    boxes: Boxes,
    world_xy: np.ndarray,
    rule: str = "smoothed",
    threshold: float = 0.10,
    window: int = 5,
) -> np.ndarray:
    """Which boxes are moving.

    Args:
        boxes: all boxes of a sequence (every frame, so tracks are complete).
        world_xy: ``(K, 2)`` world centres from :func:`world_centres`.
        rule: ``"paper"`` or ``"smoothed"`` (see the module docstring).
        threshold: displacement per frame interval above which an object moves [m].
        window: half-width of the smoothed rule's fit, in frames.

    Returns:
        ``(K,) bool``. A track seen in a single frame counts as static.
    """
    if rule not in MOVING_RULES:
        raise ValueError(f"unknown moving rule {rule!r}; choose from {', '.join(MOVING_RULES)}")
    if window < 1:
        raise ValueError(f"window must be >= 1 frame, got {window}")
    moving = np.zeros(len(boxes), dtype=bool)
    for tid in np.unique(boxes.track):
        idx = np.flatnonzero(boxes.track == tid)
        idx = idx[np.argsort(boxes.frame[idx], kind="stable")]
        f = boxes.frame[idx].astype(np.float64)
        p = world_xy[idx]
        if len(idx) < 2:
            continue
        if rule == "paper":
            step = np.hypot(*np.diff(p, axis=0).T) / np.diff(f)  # per frame interval
            per = np.concatenate([step[:1], step])  # first frame: its next step
            moving[idx] = per > threshold
            continue
        for k in range(len(idx)):
            near = np.abs(f - f[k]) <= window
            if near.sum() < 2:
                continue
            fk, pk = f[near], p[near]
            fc = fk - fk.mean()
            slope = (fc @ (pk - pk.mean(axis=0))) / (fc @ fc)  # (2,) m per frame
            moving[idx[k]] = float(np.hypot(*slope)) > threshold
    return moving
