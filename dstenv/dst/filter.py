"""The stateful perception-grid filter: one call per LIDAR sweep."""

from __future__ import annotations

import numpy as np

from dstenv.dst._kernel import REACHABLE, fused_update, padded_grid, sensor_map_weights
from dstenv.dst.frame import NUM_CLASSES, NUM_SETS, OMEGA
from dstenv.dst.params import DSTParams

__all__ = ["PerceptionGridFilter"]


class PerceptionGridFilter:
    """Map-aided evidential grid over (navigable, non_navigable, building, static, moving).

    Implements ``dst-spec.md`` steps 1-8 with a fused numba kernel that visits only the
    15 subsets that can carry mass (:data:`dstenv.dst._kernel.REACHABLE`) and computes
    BetP in the same pass; the result equals
    :func:`dstenv.dst.reference.reference_update` to float32 rounding.

    Args:
        shape: ``(H, W)`` of the ego-centred grid (axes as in :mod:`dstenv.grid`).
        params: the update's numbers (default :meth:`DSTParams.default`).
        cell_size: cell edge [m], used to apply the ego motion.

    Attributes:
        masses: ``(32, H, W) float32`` current perception grid (read-only view).
        zeta: ``(H, W) float32`` accumulator, 0 = possibly moving, 1 = stationary.

    Example:
        >>> f = PerceptionGridFilter((256, 256))
        >>> m = f.update(sensor_states, map_classes, ego_motion=(0.5, 0.0, 0.01))
        >>> betp = f.pignistic()          # (5, 256, 256)
    """

    def __init__(
        self, shape: tuple[int, int], params: DSTParams | None = None, cell_size: float = 0.33
    ) -> None:
        h, w = (int(v) for v in shape)
        if h < 1 or w < 1:
            raise ValueError(f"grid shape must be positive, got {shape}")
        if not cell_size > 0:
            raise ValueError(f"cell_size must be > 0 m, got {cell_size}")
        self.shape = (h, w)
        self.cell_size = float(cell_size)
        self.params = params if params is not None else DSTParams.default()
        self._wsm, self._sm_free, self._sm_occ = sensor_map_weights(self.params)
        # Two buffers whose unreachable sets stay 0 forever; updates write the other one.
        self._buf = [padded_grid(NUM_SETS, (h, w)) for _ in range(2)]
        self._zbuf = [np.zeros((h, w), np.float32) for _ in range(2)]
        self._betp = padded_grid(NUM_CLASSES, (h, w))
        self._cur = 0
        self.reset()

    def reset(self) -> None:
        """Back to total ignorance: m(Omega) = 1 and zeta = 0 everywhere."""
        for buf, zbuf in zip(self._buf, self._zbuf):
            buf[REACHABLE] = 0.0
            buf[OMEGA] = 1.0
            zbuf[:] = 0.0
        self._betp[...] = 1.0 / NUM_CLASSES
        self._cur = 0

    @property
    def masses(self) -> np.ndarray:
        """``(32, H, W) float32`` current grid, a read-only view valid until the next update."""
        view = self._buf[self._cur].view()
        view.flags.writeable = False
        return view

    @property
    def zeta(self) -> np.ndarray:
        """``(H, W) float32`` current accumulator (read-only view)."""
        view = self._zbuf[self._cur].view()
        view.flags.writeable = False
        return view

    def update(
        self,
        sensor_states: np.ndarray,
        map_classes: np.ndarray,
        ego_motion: tuple[float, float, float] | None = None,
        *,
        copy: bool = True,
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
        warp_on = (dx, dy, dyaw) != (0.0, 0.0, 0.0)
        nxt = 1 - self._cur
        p = self.params
        fused_update(
            self._buf[self._cur], self._zbuf[self._cur], sensor, gis,
            dx, dy, dyaw, self.cell_size, warp_on,
            p.alpha, p.delta_inc, p.delta_dec, p.gamma_occupied, p.gamma_conflict,
            self._wsm, self._sm_free, self._sm_occ,
            self._buf[nxt], self._zbuf[nxt], self._betp,
        )
        self._cur = nxt
        return np.ascontiguousarray(self._buf[nxt]) if copy else self.masses

    def pignistic(self, out: np.ndarray | None = None) -> np.ndarray:
        """BetP of the current grid: ``(5, H, W) float32`` over ``CLASSES``.

        Computed by the update itself, so this is a copy (into ``out`` if given).
        """
        if out is None:
            return np.ascontiguousarray(self._betp)
        out[...] = self._betp
        return out

    def _codes(self, grid: np.ndarray, max_code: int, name: str) -> np.ndarray:
        grid = np.asarray(grid)
        if grid.shape != self.shape:
            raise ValueError(f"{name} must have shape {self.shape}, got {grid.shape}")
        if grid.dtype != np.uint8:
            if not np.issubdtype(grid.dtype, np.integer):
                raise ValueError(f"{name} must hold integer codes, got dtype {grid.dtype}")
            grid = grid.astype(np.uint8)
        if grid.max(initial=0) > max_code:
            raise ValueError(f"{name} holds code {int(grid.max())}; allowed codes are 0..{max_code}")
        return np.ascontiguousarray(grid)
