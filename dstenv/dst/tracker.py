"""The DST filter over time: the one loop behind the simulator, KITTI and replay.

A :class:`GridTracker` owns a :class:`~dstenv.dst.PerceptionGridFilter`, the pose of
the previous *fused* frame and the BetP it produced. Each :meth:`GridTracker.step`
takes ``(sensor grid, GIS grid, ego pose)``, moves the filter by the relative pose
since the previous fused frame (:func:`dstenv.grid.relative_pose`) and returns BetP
at t and at t-1, where t-1 is the previous fused frame (the paper fused at 1 Hz or
0.5 Hz: t-1 is then 1 s or 2 s earlier, not one LIDAR period). The first step after
:meth:`GridTracker.reset` has no past: its t-1 is BetP at t.

Callers decide *which* frames are fused (``dst.update_every`` in the pipeline,
``update_every`` in KITTI conversion); frames in between are not seen here. A fused
frame whose BetP nobody keeps (data generation at a stride above the fusion period)
is stepped with ``betp=False``: the update skips BetP (~15 % of it at 256 x 256),
and the next ``step()`` with BetP, or :meth:`GridTracker.latest`, computes the t-1 it
needs from the masses, which are still those of the skipped frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dstenv.dst.filter import PerceptionGridFilter
from dstenv.dst.frame import NUM_CLASSES
from dstenv.dst.params import DSTParams
from dstenv.grid import relative_pose

__all__ = ["GridTracker", "TrackerStep"]


@dataclass
class TrackerStep:
    """The result of one fused frame.

    Attributes:
        betp: ``(5, H, W) float32`` BetP at t (a fresh array); None if the step
            skipped it (``betp=False``).
        betp_prev: ``(5, H, W) float32`` BetP of the previous fused frame (``betp``
            itself on the first step); None if the step skipped BetP.
        masses: ``(32, H, W) float32`` perception grid at t: a copy when asked for
            with ``masses=True``, else the filter's read-only view, valid until the
            next step.
    """

    betp: np.ndarray | None
    betp_prev: np.ndarray | None
    masses: np.ndarray


class GridTracker:
    """A perception-grid filter stepped with ego poses.

    Args:
        shape: ``(H, W)`` grid shape [cells].
        params: DST parameters (default: :meth:`DSTParams.default`).
        cell_size: [m].
        threads: filter threads (see :class:`PerceptionGridFilter`).

    Attributes:
        filter: the underlying :class:`PerceptionGridFilter`.
        prev_pose: ``(3,) float64`` pose of the last fused frame, or ``None``.
        prev_betp: ``(5, H, W) float32`` BetP of the last fused frame, or ``None``
            (before the first step, or when the last step skipped BetP).
        steps: fused frames since the last reset.
    """

    def __init__(self, shape: tuple[int, int], params: DSTParams | None = None,
                 cell_size: float = 0.33, *, threads: int = 1) -> None:
        self.filter = PerceptionGridFilter(shape, params, cell_size, threads=threads)
        self.prev_pose: np.ndarray | None = None
        self.prev_betp: np.ndarray | None = None
        self._last_prev: np.ndarray | None = None  # t-1 of the last step, if known
        self._skipped = False  # the last step skipped BetP (prev_betp is None)
        self.steps = 0

    def reset(self) -> None:
        """Back to total ignorance, with no previous frame."""
        self.filter.reset()
        self.prev_pose = None
        self.prev_betp = self._last_prev = None
        self._skipped = False
        self.steps = 0

    def step(self, sensor: np.ndarray, gis: np.ndarray, pose: np.ndarray, *,
             masses: bool = False, betp: bool = True) -> TrackerStep:
        """Fuse one frame.

        Args:
            sensor: ``(H, W) uint8`` sensor grid (0 unknown, 1 free, 2 occupied).
            gis: ``(H, W) uint8`` GIS grid (:class:`dstenv.sim.types.MapClass` codes).
            pose: ``(3,) float`` ego world pose ``(x [m], y [m], yaw [rad])``.
            masses: return a copy of the masses (else the read-only view).
            betp: compute BetP (default). ``False`` skips it, for a frame nobody
                keeps: ``betp`` and ``betp_prev`` of the result are None, and a later
                step with BetP computes its t-1 from the masses this step leaves. Two
                skipped steps in a row lose the first one's BetP: :meth:`latest` after
                them raises (the pipeline skips only when every step is fused, so a
                frame is always built on a step with BetP).

        Returns:
            A :class:`TrackerStep`.
        """
        pose = np.asarray(pose, dtype=np.float64)
        if pose.shape != (3,) or not np.isfinite(pose).all():
            raise ValueError(f"GridTracker.step: pose must be a finite (3,) array, got {pose!r}")
        motion = None if self.prev_pose is None else relative_pose(self.prev_pose, pose)
        self.prev_pose = pose.copy()
        self.steps += 1
        if not betp:
            last_prev = None if self._skipped else self.prev_betp  # this step's t-1, if known
            m = self.filter.update(sensor, gis, motion, copy=masses, pignistic=False)
            self._last_prev, self.prev_betp, self._skipped = last_prev, None, True
            return TrackerStep(betp=None, betp_prev=None, masses=m)
        if self._skipped:  # the masses are still the last frame's: its BetP, computed now
            self.prev_betp, self._skipped = _read_only(self.filter.pignistic()), False
        # the kernel writes BetP straight into this frame's own array (no copy)
        out = np.empty((NUM_CLASSES, *self.filter.shape), np.float32)
        m = self.filter.update(sensor, gis, motion, copy=masses, betp=out)
        out.flags.writeable = False  # shared with the next frame (its t-1): never changed
        prev = out if self.prev_betp is None else self.prev_betp
        self.prev_betp, self._last_prev = out, prev
        return TrackerStep(betp=out, betp_prev=prev, masses=m)

    def latest(self) -> tuple[np.ndarray, np.ndarray]:
        """BetP at t and t-1 of the last fused frame, ``(5, H, W) float32`` each (the
        first frame after a reset: t-1 is t); a skipped BetP is computed here from the
        masses, once.

        Raises:
            RuntimeError: before the first step, or when the last two steps both
                skipped BetP (t-1 is gone).
        """
        if self.steps == 0:
            raise RuntimeError("GridTracker.latest: no fused frame since the reset")
        if self._skipped:
            if self._last_prev is None and self.steps > 1:
                raise RuntimeError("GridTracker.latest: the last two fused frames skipped "
                                   "BetP (step(betp=False)), so t-1 is gone")
            self.prev_betp, self._skipped = _read_only(self.filter.pignistic()), False
            if self._last_prev is None:  # the first frame: t-1 is t
                self._last_prev = self.prev_betp
        assert self.prev_betp is not None and self._last_prev is not None
        return self.prev_betp, self._last_prev


def _read_only(a: np.ndarray) -> np.ndarray:
    """``a``, marked read-only (a BetP that frames share)."""
    a.flags.writeable = False
    return a
