"""Geometry of the ego-centred grid: the one place that defines the axis convention.

Frames
------
* **World frame**: metres, x east, y north, yaw counter-clockwise from +x.
* **Ego frame**: metres, origin at the ego (LIDAR) position, x forward, y left
  (the Velodyne / ISO 8855 convention).

Grid arrays
-----------
Every ego-centred grid (sensor, GIS, labels, masses, probabilities) has shape
``(..., H, W)``. Row ``i`` and column ``j`` index the cell whose centre is at ::

    x = (i0 - i) * cell_size      # ego-forward is *up* (row 0 is the far front)
    y = (j0 - j) * cell_size      # ego-left is *left* (column 0 is the far left)

with the ego cell ``(i0, j0) = (H // 2, W // 2)``. Plotting a grid with
``imshow`` therefore shows the scene as a driver sees it from above: forward up,
left left. Cell ``(i, j)`` covers ``x in (x_c - c/2, x_c + c/2]`` around its centre
``x_c`` (the upper edge belongs to the cell, as :meth:`GridSpec.to_cell` rounds), and
likewise in y.

The paper's default is 256 x 256 cells of 0.33 m (84.5 m square), ego at the centre.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["GridSpec", "relative_pose", "SECTION", "camera_mask"]


@dataclass(frozen=True)
class GridSpec:
    """Size and resolution of an ego-centred grid.

    Args:
        height: number of rows H (along ego x, forward up).
        width: number of columns W (along ego y, left left).
        cell_size: edge length of a square cell [m].
    """

    height: int = 256
    width: int = 256
    cell_size: float = 0.33

    def __post_init__(self) -> None:
        if self.height < 2 or self.width < 2:
            raise ValueError(f"grid must be at least 2x2 cells, got {self.height}x{self.width}")
        if not self.cell_size > 0:
            raise ValueError(f"cell_size must be > 0 m, got {self.cell_size}")

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)``."""
        return (self.height, self.width)

    @property
    def ego_cell(self) -> tuple[int, int]:
        """``(i0, j0)``: row and column of the cell containing the ego."""
        return (self.height // 2, self.width // 2)

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """``(x_min, x_max, y_min, y_max)`` [m] of the area covered, in the ego frame."""
        i0, j0 = self.ego_cell
        c = self.cell_size
        return (
            (i0 - self.height + 0.5) * c,
            (i0 + 0.5) * c,
            (j0 - self.width + 0.5) * c,
            (j0 + 0.5) * c,
        )

    def cell_centers(self) -> tuple[np.ndarray, np.ndarray]:
        """Ego-frame coordinates of every cell centre.

        Returns:
            ``(x, y)``, each ``(H, W) float64`` [m].
        """
        i0, j0 = self.ego_cell
        rows = (i0 - np.arange(self.height, dtype=np.float64)) * self.cell_size
        cols = (j0 - np.arange(self.width, dtype=np.float64)) * self.cell_size
        return (np.broadcast_to(rows[:, None], self.shape),
                np.broadcast_to(cols[None, :], self.shape))

    def to_cell(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rows and columns of the cells containing ego-frame points.

        Args:
            x, y: ego-frame coordinates [m], any equal shapes.

        Returns:
            ``(i, j)`` int64 arrays of the same shape; they may lie outside the grid
            (use :meth:`inside`).
        """
        i0, j0 = self.ego_cell
        i = np.floor(i0 - np.asarray(x) / self.cell_size + 0.5).astype(np.int64)
        j = np.floor(j0 - np.asarray(y) / self.cell_size + 0.5).astype(np.int64)
        return i, j

    def inside(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """Boolean mask of cell indices that lie in the grid."""
        return (i >= 0) & (i < self.height) & (j >= 0) & (j < self.width)


def relative_pose(prev_pose: np.ndarray, pose: np.ndarray) -> tuple[float, float, float]:
    """Pose of ``pose`` expressed in the ego frame of ``prev_pose``.

    This is the ``ego_motion`` argument of
    :meth:`dstenv.dst.PerceptionGridFilter.update`.

    Args:
        prev_pose: ``(3,)`` world pose ``(x, y, yaw)`` at t-1 [m, m, rad].
        pose: ``(3,)`` world pose at t.

    Returns:
        ``(dx, dy, dyaw)``: translation [m] in the previous ego frame and yaw change
        [rad], wrapped to ``(-pi, pi]``.
    """
    px, py, pyaw = (float(v) for v in prev_pose)
    x, y, yaw = (float(v) for v in pose)
    c, s = np.cos(pyaw), np.sin(pyaw)
    dxw, dyw = x - px, y - py
    dyaw = (yaw - pyaw + np.pi) % (2 * np.pi) - np.pi
    if dyaw == -np.pi:
        dyaw = np.pi
    return (c * dxw + s * dyw, -s * dxw + c * dyw, float(dyaw))


def _grid_defaults() -> dict[str, int | float]:
    spec = GridSpec()
    return {
        "height": spec.height,  # [cells] rows, along ego-forward
        "width": spec.width,  # [cells] columns, along ego-left
        "cell_size": spec.cell_size,  # [m]
    }


def _section() -> "object":
    from dstenv.config import Section, between

    # 4096 x 4096 cells of 32 float32 masses is 2 GiB: beyond that a grid would not
    # fit this library's intended machines
    return Section(_grid_defaults, {
        "height": between(2, 4096, "cells"),
        "width": between(2, 4096, "cells"),
        "cell_size": between(0.01, 10.0, "m"),
    })


#: The ``grid`` section of the configuration (:func:`dstenv.config.build_config`).
SECTION = _section()


def camera_mask(spec: GridSpec, fov_deg: float) -> np.ndarray:
    """Cells inside a forward camera's horizontal field of view (an ideal camera at the
    ego, as the simulated drives' ``protocol.camera_fov``; KITTI's own, from its
    calibration: :func:`dstenv.kitti.grids.camera_fov`).

    Args:
        spec: grid geometry (the camera at the ego cell, looking along +x).
        fov_deg: full horizontal field of view [deg], in (0, 180).

    Returns:
        ``(H, W) bool``: cell centres ahead of the ego within ``fov_deg / 2`` of +x.

    Raises:
        ValueError: ``fov_deg`` outside (0, 180) (NaN too).
    """
    if not 0.0 < fov_deg < 180.0:
        raise ValueError(f"camera_mask: fov_deg must lie in (0, 180), got {fov_deg!r}")
    x, y = spec.cell_centers()
    return (x > 0) & (np.abs(np.arctan2(y, x)) <= np.deg2rad(fov_deg) / 2)
