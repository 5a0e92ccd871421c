"""The ego motion the DST filter is given: true, or with the errors of a real INS.

The filter moves its state by the relative pose between two fused frames. In the
simulator that pose is exact; on KITTI it comes from the OXTS unit, whose steps
disagree with a scan-to-scan ICP registration (``docs/kitti_pose_check.py``,
``docs/kitti-pose-check.json``) by up to 9 cm along the track (alternating from step to
step: timestamp jitter), by an across-track error that keeps its sign and grows
(1 to 7 cm a step over 4 s) and by up to 0.05 deg of yaw. :class:`Odometry` gives the
filter such a pose estimate, per fused step::

    along  += N(0, along)             (white, per step)           [m]
    b      += N(0, drift);  across += b   (a random walk of the step's error) [m]
    yaw    += N(0, yaw)               (white, per step)           [deg]

composed onto the previous estimate; the labels, the sensor grid and every other
output keep the true pose. All zero (the default) returns the true pose itself, bit
for bit. Draws come from a generator keyed by the episode seed only, in fused-step
order, so one seed gives one drive.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from dstenv.grid import relative_pose

__all__ = ["Odometry", "ODOMETRY_KEYS"]

#: ``protocol`` keys of the model: std of the along-track step error [m], std of the
#: per-step change of the across-track step error [m], std of the yaw step error [deg]
ODOMETRY_KEYS: tuple[str, ...] = ("odometry_along", "odometry_drift", "odometry_yaw")


class Odometry:
    """Pose estimates with a real INS's step errors (see the module docstring).

    Args:
        config: the ``protocol`` section (its :data:`ODOMETRY_KEYS`).
    """

    def __init__(self, config: Mapping[str, Any]) -> None:
        self.along = float(config["odometry_along"])
        self.drift = float(config["odometry_drift"])
        self.yaw = math.radians(float(config["odometry_yaw"]))
        self.exact = self.along == 0.0 and self.drift == 0.0 and self.yaw == 0.0
        self.reset(0)

    def reset(self, seed: int) -> None:
        """Start an episode: the next pose is taken as it is."""
        self._rng = np.random.default_rng([int(seed), 0x0D0])
        self._true: np.ndarray | None = None
        self._est: np.ndarray | None = None
        self._bias = 0.0

    def estimate(self, pose: np.ndarray) -> np.ndarray:
        """The filter's pose for the true ``(3,)`` world ``pose`` of a fused step.

        Returns:
            ``(3,) float64``: ``pose`` itself when the model is off.
        """
        if self.exact:
            return pose
        pose = np.asarray(pose, dtype=np.float64)
        if self._true is None:
            est = pose.copy()
        else:
            dx, dy, dyaw = relative_pose(self._true, pose)
            r = self._rng.standard_normal(3)
            self._bias += self.drift * r[1]
            dx += self.along * r[0]
            dy += self._bias
            dyaw += self.yaw * r[2]
            x, y, h = self._est
            c, s = math.cos(h), math.sin(h)
            est = np.array([x + c * dx - s * dy, y + s * dx + c * dy, h + dyaw])
        self._true, self._est = pose.copy(), est
        return est
