"""The stateful perception-grid filter: one call per LIDAR sweep."""

from __future__ import annotations

import os
import threading

import numpy as np

from dstenv.dst._kernel import (
    REACHABLE, ROW_PLANES, fused_update, grid_view, history_rows, inplace_update, kernel_params,
    pignistic_planes, plane_grid,
)
from dstenv.dst.frame import NUM_CLASSES, NUM_SETS, OMEGA
from dstenv.dst.params import DSTParams

__all__ = ["PerceptionGridFilter", "IN_PLACE_MIN_CELLS"]

#: grids of at least this many cells are updated in place with one thread: 10-20 %
#: faster at 256 x 256, where the state (~4 MB) streams from memory; at 64 x 64 and
#: 128 x 128 the double buffer was as fast or ~10 % faster (one process, loaded machine)
IN_PLACE_MIN_CELLS = 256 * 256 // 2


class PerceptionGridFilter:
    """Map-aided evidential grid over (navigable, non_navigable, building, static, moving).

    Implements ``dst-spec.md`` steps 1-8 with a generated numba kernel
    (:mod:`dstenv.dst._codegen`) that visits only the 15 subsets that can carry mass
    (:data:`dstenv.dst._kernel.REACHABLE`), runs vectorised across each grid row in
    float32 and computes BetP in the same pass; the result equals
    :func:`dstenv.dst.reference.reference_update` to float32 rounding (< 1e-6).

    Fast path: ``update(..., copy=False)`` followed by :meth:`pignistic` (what
    :mod:`dstenv.pipeline` does) touches only the 15 reachable planes; ``copy=True``
    (the default) adds a copy of the whole ``(32, H, W)`` grid.

    Args:
        shape: ``(H, W)`` of the ego-centred grid (axes as in :mod:`dstenv.grid`).
        params: the update's numbers (default :meth:`DSTParams.default`).
        cell_size: cell edge [m], used to apply the ego motion.
        threads: split each update into this many bands of rows, run in parallel
            (default 1). Results are bit-identical for any value. Extra threads are
            plain Python threads started per update (the kernel releases the GIL), so
            nothing persists across ``fork``; they only pay on otherwise idle cores:
            when the cores are busy a band that waits for a time slice stalls the
            whole update. With one thread a grid of :data:`IN_PLACE_MIN_CELLS` or
            more is updated in place (rows in the order the motion allows, a small
            ring of overwritten rows for sources behind the current row): less
            memory traffic than the double buffer that bands of rows need. Results
            are the same bits either way.

    Attributes:
        masses: ``(32, H, W) float32`` current perception grid (read-only view).
        zeta: ``(H, W) float32`` accumulator, 0 = possibly moving, 1 = stationary.

    Example:
        >>> f = PerceptionGridFilter((256, 256))
        >>> m = f.update(sensor_states, map_classes, ego_motion=(0.5, 0.0, 0.01))
        >>> betp = f.pignistic()          # (5, 256, 256)
    """

    def __init__(
        self,
        shape: tuple[int, int],
        params: DSTParams | None = None,
        cell_size: float = 0.33,
        *,
        threads: int = 1,
    ) -> None:
        if (not isinstance(shape, (tuple, list)) or len(shape) != 2 or not all(
                isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 1
                for v in shape)):  # (64.7 was 64, 64 an 'int is not iterable')
            raise ValueError(f"grid shape must be two integers >= 1 (H, W), got {shape!r}")
        h, w = (int(v) for v in shape)
        if params is not None and not isinstance(params, DSTParams):
            raise TypeError(f"params: a DSTParams (DSTParams.from_dict(d) for a dict), got "
                            f"{type(params).__name__}")
        if not cell_size > 0:
            raise ValueError(f"cell_size must be > 0 m, got {cell_size}")
        most = os.cpu_count() or 1
        if not isinstance(threads, (int, np.integer)) or not 1 <= threads <= most:
            raise ValueError(
                f"threads must be an integer in 1..{most} (the CPU count), got {threads!r}"
            )
        self.shape = (h, w)
        self.cell_size = float(cell_size)
        self.threads = int(threads)
        self._bands = np.linspace(0, h, min(self.threads, h) + 1).round().astype(int).tolist()
        self.params = params if params is not None else DSTParams.default()
        self._prm = kernel_params(self.params)
        # State buffers (flat planes with a vacuous pad, see _kernel): one, updated in
        # place, for one thread; two for bands of rows (updates write the other one).
        # The unreachable sets stay 0 forever.
        self._in_place = self.threads == 1 and h * w >= IN_PLACE_MIN_CELLS
        n_buf = 1 if self._in_place else 2
        self._buf = [plane_grid(NUM_SETS, (h, w)) for _ in range(n_buf)]
        self._zbuf = [plane_grid(1, (h, w))[0] for _ in range(n_buf)]
        self._hist = np.empty((ROW_PLANES, w), np.float32)  # in-place ring, grown on demand
        self._betp = plane_grid(NUM_CLASSES, (h, w))
        self._betp_now = self._betp  # where the last update wrote BetP ((5, >= H*W) planes)
        self._cur = 0
        self.reset()

    def reset(self) -> None:
        """Back to total ignorance: m(Omega) = 1 and zeta = 0 everywhere."""
        for buf, zbuf in zip(self._buf, self._zbuf):
            buf[REACHABLE] = 0.0
            buf[OMEGA] = 1.0  # the pad columns too: they stand for "outside the grid"
            zbuf[:] = 0.0
        self._betp[...] = 1.0 / NUM_CLASSES
        self._betp_now = self._betp
        self._cur = 0

    @property
    def masses(self) -> np.ndarray:
        """``(32, H, W) float32`` current grid, a read-only view valid until the next update."""
        view = grid_view(self._buf[self._cur], self.shape)
        view.flags.writeable = False
        return view

    @property
    def zeta(self) -> np.ndarray:
        """``(H, W) float32`` current accumulator (read-only view)."""
        view = grid_view(self._zbuf[self._cur][None], self.shape)[0]
        view.flags.writeable = False
        return view

    def update(
        self,
        sensor_states: np.ndarray,
        map_classes: np.ndarray,
        ego_motion: tuple[float, float, float] | None = None,
        *,
        copy: bool = True,
        betp: np.ndarray | None = None,
        pignistic: bool = True,
    ) -> np.ndarray:
        """Fuse one sweep and one map cut into the grid.

        Args:
            sensor_states: ``(H, W) uint8``: 0 unknown, 1 free, 2 occupied.
            map_classes: ``(H, W) uint8``: 0 none, 1 building, 2 road, 3 intermediate.
            ego_motion: ``(dx [m], dy [m], dyaw [rad])``: the current ego pose in the
                previous ego frame (:func:`dstenv.grid.relative_pose`); ``None`` when
                the ego did not move.
            copy: return a fresh array (default). ``False`` returns the read-only
                :attr:`masses` view, valid until the next update: the fast path.
            betp: optional ``(5, H, W) float32`` C-contiguous array the update writes
                BetP into directly (instead of its own buffer): a caller that keeps
                every frame's BetP (:class:`dstenv.dst.tracker.GridTracker`) saves
                the copy :meth:`pignistic` makes. :meth:`pignistic` reads it until
                the next update or reset, so leave it unchanged until then.
            pignistic: compute BetP in the update (default). ``False`` skips it
                (numba compiles the kernel's ``betp=None`` case without it: ~15 % of a
                256 x 256 update) for an update whose BetP nobody reads;
                :meth:`pignistic` then computes it from the masses, the same bits.

        Returns:
            ``(32, H, W) float32`` perception grid at t.
        """
        sensor = self._codes(sensor_states, 2, "sensor_states")
        gis = self._codes(map_classes, 3, "map_classes")
        if ego_motion is None:
            dx = dy = dyaw = 0.0
        else:
            if len(ego_motion) != 3:
                raise ValueError(f"ego_motion must be (dx, dy, dyaw), got {ego_motion!r}")
            dx, dy, dyaw = (float(v) for v in ego_motion)
            if not np.isfinite([dx, dy, dyaw]).all():
                raise ValueError(f"ego_motion must be finite, got {ego_motion!r}")
        warp_on = (dx, dy, dyaw) != (0.0, 0.0, 0.0)
        # cos/sin by numpy, as reference.source_cells, so both pick the same source cells
        geo = np.array([np.cos(dyaw), np.sin(dyaw), dx, dy, self.cell_size])
        if not pignistic:
            self._betp_now = None  # pignistic() computes it from the state if asked
        else:
            self._betp_now = self._betp if betp is None else self._betp_target(betp)
        if self._in_place:
            k_hist, desc = history_rows(geo, self.shape) if warp_on else (0, False)
            if k_hist * self.shape[1] > self._hist.shape[1]:
                self._hist = np.empty((ROW_PLANES, k_hist * self.shape[1]), np.float32)
            inplace_update(self._buf[0], self._zbuf[0], sensor, gis, warp_on, geo, self._prm,
                           self._betp_now, self._hist, k_hist, desc)
            return self.masses.copy() if copy else self.masses
        nxt = 1 - self._cur
        args = (
            self._buf[self._cur], self._zbuf[self._cur], sensor, gis, warp_on, geo, self._prm,
            self._buf[nxt], self._zbuf[nxt], self._betp_now,
        )
        # bands of rows: extra ones in threads, the first in this thread
        workers = [
            threading.Thread(target=fused_update, args=(*args, first, stop))
            for first, stop in zip(self._bands[1:-1], self._bands[2:])
        ]
        for worker in workers:
            worker.start()
        fused_update(*args, self._bands[0], self._bands[1])
        for worker in workers:
            worker.join()
        self._cur = nxt
        return self.masses.copy() if copy else self.masses

    def pignistic(self, out: np.ndarray | None = None) -> np.ndarray:
        """BetP of the current grid: ``(5, H, W) float32`` over ``CLASSES``.

        Computed by the update itself, so this is a copy (into ``out`` if given); after
        an update with ``pignistic=False`` it is computed here from the masses (the
        update's arithmetic, the same bits).
        """
        if self._betp_now is None:
            h, w = self.shape
            pignistic_planes(self._buf[self._cur], self._betp, h * w)
            self._betp_now = self._betp
        betp = grid_view(self._betp_now, self.shape)
        if out is None:
            return betp.copy()
        out[...] = betp
        return out

    def _betp_target(self, betp: np.ndarray) -> np.ndarray:
        """``betp`` as the kernel's ``(5, H * W)`` planes (a view), or ValueError."""
        shape = (NUM_CLASSES, *self.shape)
        if (not isinstance(betp, np.ndarray) or betp.shape != shape
                or betp.dtype != np.float32 or not betp.flags.c_contiguous
                or not betp.flags.writeable):
            got = (f"{betp.dtype} {betp.shape}" if isinstance(betp, np.ndarray)
                   else type(betp).__name__)
            raise ValueError(f"betp must be a writeable C-contiguous float32 array of shape "
                             f"{shape}, got {got}")
        return betp.reshape(NUM_CLASSES, -1)

    def _codes(self, grid: np.ndarray, max_code: int, name: str) -> np.ndarray:
        grid = np.asarray(grid)
        if grid.shape != self.shape:
            raise ValueError(f"{name} must have shape {self.shape}, got {grid.shape}")
        if grid.dtype != np.uint8 and not np.issubdtype(grid.dtype, np.integer):
            raise ValueError(f"{name} must hold integer codes, got dtype {grid.dtype}")
        # before any cast: 257 must not wrap to 1 (a min pass only where codes can be < 0)
        lo = int(grid.min(initial=0)) if np.issubdtype(grid.dtype, np.signedinteger) else 0
        hi = int(grid.max(initial=0))
        if lo < 0 or hi > max_code:
            raise ValueError(f"{name} holds code {lo if lo < 0 else hi}; allowed codes "
                             f"are 0..{max_code}")
        if grid.dtype != np.uint8:
            grid = grid.astype(np.uint8)
        return np.ascontiguousarray(grid)
