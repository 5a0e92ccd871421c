"""One labelled perception-grid frame: the record every producer emits.

The simulator pipeline (:mod:`dstenv.pipeline`), the highway-env backend and the
KITTI converter all produce :class:`Frame` objects; the shard writer stores them and
the datasets read them back. Grid axes follow :mod:`dstenv.grid`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Frame", "IGNORE_INDEX"]

#: Label value of cells excluded from training losses and metrics (e.g. KITTI
#: ``DontCare`` regions). Never a class index: classes are 0..4.
IGNORE_INDEX: int = 255


@dataclass
class Frame:
    """A perception grid with its inputs and exact labels at one time step.

    Attributes:
        pignistic: ``(5, H, W) float32`` BetP over ``dstenv.dst.CLASSES`` at t (None,
            with ``pignistic_prev``, from a pipeline that does not fuse:
            ``Pipeline(fuse=False)``, whose grids a batched filter fuses elsewhere).
        pignistic_prev: ``(5, H, W) float32`` BetP at t-1 (equal to ``pignistic``
            on the first frame of an episode). Stacked, the two are the paper's
            10-channel FCN input. From a :class:`~dstenv.pipeline.Pipeline` both are
            read-only and shared, not copied: one frame's t is the next one's t-1 (and,
            between fused steps, the next one's t too); copy them to change them.
        labels: ``(H, W) uint8`` ground truth, class index in ``dstenv.dst.CLASSES``
            order, or :data:`IGNORE_INDEX`; ``None`` when the producer was told not
            to compute labels (``frame.labels = false`` in the pipeline config, the
            RL env's default unless ``info.labels`` is set).
        visible: ``(H, W) bool`` cells the sensor observed (not unknown) this sweep;
            ``None`` together with ``labels``.
        sensor: ``(H, W) uint8`` sensor grid: 0 unknown, 1 free, 2 occupied.
        gis: ``(H, W) uint8`` GIS grid: 0 no information, 1 building, 2 road,
            3 intermediate.
        ego_pose: ``(3,) float64`` world pose ``(x [m], y [m], yaw [rad])``.
        time: simulation time [s] since the episode's reset.
        seed: the episode seed that reproduces this frame.
        step: index of the step within its episode.
        masses: optional ``(32, H, W) float32`` raw mass grid at t.
        extras: optional named arrays (e.g. LIDAR points) a producer adds.
    """

    pignistic: np.ndarray | None
    pignistic_prev: np.ndarray | None
    labels: np.ndarray | None
    visible: np.ndarray | None
    sensor: np.ndarray
    gis: np.ndarray
    ego_pose: np.ndarray
    time: float = 0.0
    seed: int = 0
    step: int = 0
    masses: np.ndarray | None = None
    extras: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)`` of the grids."""
        return tuple(self.sensor.shape)  # type: ignore[return-value]

    def fcn_input(self) -> np.ndarray:
        """The paper's FCN input: ``(10, H, W) float32``, BetP at t then at t-1."""
        return np.concatenate([self.pignistic, self.pignistic_prev], axis=0)
