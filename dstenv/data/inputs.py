"""What a segmentation network reads (``inputs``) and which labels it learns (``labels``):
one home for the channel stacks of :mod:`dstenv.data.datasets` (stored shards and
streams) and of :mod:`dstenv.segment.score` (replayed and KITTI frames).

See :mod:`dstenv.data.datasets` for the ``inputs`` and ``labels`` names. Split from it
to keep both modules small; it re-exports everything here.
"""

from __future__ import annotations

import numpy as np

__all__ = ["INPUTS", "INPUT_CHANNELS", "LABELS", "PAST_STEPS", "sensor_channels",
           "network_input", "past_sensor", "past_rows"]

#: ``inputs`` name -> shard datasets stacked into ``x``
INPUTS: dict[str, tuple[str, ...]] = {
    "fcn10": ("pignistic", "pignistic_prev"),
    "pignistic": ("pignistic",),
    "masses": ("masses",),
    "fcn10+sensor": ("pignistic", "pignistic_prev", "sensor"),
    "fcn10+sensor+past": ("pignistic", "pignistic_prev", "sensor", "past"),
}

#: ``inputs`` name -> channels of ``x``
INPUT_CHANNELS: dict[str, int] = {"fcn10": 10, "pignistic": 5, "masses": 32, "fcn10+sensor": 12,
                                  "fcn10+sensor+past": 14}
#: steps between a frame and the past sensor grid of ``fcn10+sensor+past`` (1 s at 10 Hz)
PAST_STEPS: int = 10

#: label conventions of :class:`ShardDataset` (module docstring)
LABELS: tuple[str, ...] = ("full", "kitti")


def sensor_channels(sensor: np.ndarray) -> np.ndarray:
    """The sensor grid as network input: ``(..., H, W) uint8`` codes of
    :class:`dstenv.dst.SensorState` -> ``(..., 2, H, W) float32``, seen free then seen
    occupied (unknown cells are 0 in both)."""
    from dstenv.dst import SensorState

    s = np.asarray(sensor)
    return np.stack([s == SensorState.FREE, s == SensorState.OCCUPIED], axis=-3).astype(np.float32)


def past_sensor(prev: np.ndarray, prev_pose: np.ndarray, pose: np.ndarray,
                cell_size: float) -> np.ndarray:
    """An earlier sensor grid in the ego frame of ``pose``: ``(H, W) uint8``.

    Args:
        prev: ``(H, W) uint8`` the earlier grid.
        prev_pose, pose: ``(3,)`` world poses of the earlier frame and of t.
        cell_size: [m].

    Returns:
        Each cell the earlier grid's cell it comes from by the filter's nearest-cell
        warp (:func:`dstenv.dst.reference.source_cells`); unknown (0) from outside it.
    """
    from dstenv.dst.reference import source_cells
    from dstenv.grid import relative_pose

    si, sj, ok = source_cells(prev.shape, cell_size, relative_pose(prev_pose, pose))
    out = np.zeros(prev.shape, np.uint8)
    out[ok] = prev[si[ok], sj[ok]]
    return out


def past_rows(steps: np.ndarray) -> np.ndarray:
    """For each row of a drive's frames (``steps``: ``(N,)`` their step numbers, in
    order), the row holding step ``step - PAST_STEPS`` of the same run of increasing
    steps, or -1: ``(N,) int64``."""
    steps = np.asarray(steps, np.int64)
    out = np.full(len(steps), -1, np.int64)
    start = 0
    for i in range(len(steps)):
        if i and steps[i] <= steps[i - 1]:
            start = i  # the steps restart: another episode
        j = int(np.searchsorted(steps[start:i], steps[i] - PAST_STEPS)) + start
        if j < i and steps[j] == steps[i] - PAST_STEPS:
            out[i] = j
    return out


def network_input(x: np.ndarray, sensor: np.ndarray, inputs: str,
                  past: np.ndarray | None = None) -> np.ndarray:
    """What a network trained on ``inputs`` reads, from the BetP at t and t-1.

    Args:
        x: ``(K, 10, H, W) float32`` BetP at t then t-1 (``fcn10``).
        sensor: ``(K, H, W) uint8`` sensor grids of the same frames.
        inputs: ``"fcn10"``, ``"fcn10+sensor"`` or ``"fcn10+sensor+past"``.
        past: ``(K, H, W) uint8`` the past sensor grids (:func:`past_sensor`), for
            ``fcn10+sensor+past``.

    Returns:
        ``(K, C, H, W) float32`` (``x`` itself for ``fcn10``).
    """
    if inputs == "fcn10":
        return x
    if inputs == "fcn10+sensor":
        return np.concatenate([x, sensor_channels(sensor)], axis=1)
    if inputs == "fcn10+sensor+past":
        if past is None:
            raise ValueError("inputs 'fcn10+sensor+past' need the past sensor grids")
        return np.concatenate([x, sensor_channels(sensor), sensor_channels(past)], axis=1)
    raise ValueError(f"a network on inputs {inputs!r} cannot be scored from BetP at t and "
                     "t-1; scorable: fcn10, fcn10+sensor, fcn10+sensor+past")


def _check_inputs(inputs: str, single_frames: bool = False) -> tuple[str, ...]:
    """The stacked names of ``inputs``; ``single_frames``: refuse inputs that read an
    earlier frame of the drive (frames one at a time, a stream)."""
    if not isinstance(inputs, str) or inputs not in INPUTS:  # (a list: 'unhashable')
        raise ValueError(f"unknown inputs {inputs!r}; choose from {', '.join(INPUTS)}")
    if single_frames and "past" in INPUTS[inputs]:
        raise ValueError(f"inputs {inputs!r} read an earlier frame of the drive: use stored "
                         "shards (ShardDataset), not a StreamingDataset or single frames")
    return INPUTS[inputs]


def _check_labels(labels: str) -> str:
    if not isinstance(labels, str) or labels not in LABELS:
        raise ValueError(f"unknown labels {labels!r}; choose from {', '.join(LABELS)}")
    return labels
