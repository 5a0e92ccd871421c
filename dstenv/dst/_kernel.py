"""Run-time parameters and state buffers for the generated update kernel in ``_fused.py``.

Only 15 of the 32 subsets can ever carry mass in a filter state (the intersection
closure of the sensor-and-map focal sets, their specialisations and {M});
:mod:`dstenv.dst._codegen` derives them and writes the kernel.

State layout the kernel expects: a grid of ``C`` channels is a ``(C, P) float32``
array of flat planes, cell ``(i, j)`` at column ``i * W + j``, with
``P >= H * W + W``. Columns ``H * W .. H * W + W - 1`` hold a vacuous cell
(m(Omega) = 1, zeta = 0) that cells coming from outside the previous grid read, so
the warp needs no special case.
"""

from __future__ import annotations

import math

import numpy as np

from dstenv.dst._fused import (
    PRM, REACHABLE, ROW_PLANES, fused_update, inplace_update, pignistic_planes,
)
from dstenv.dst.params import DSTParams

__all__ = ["REACHABLE", "ROW_PLANES", "kernel_params", "plane_grid", "grid_view",
           "fused_update", "inplace_update", "pignistic_planes", "history_rows"]


def kernel_params(params: DSTParams) -> np.ndarray:
    """The update's numbers as the kernel's ``(len(PRM),) float32`` vector (``_fused.PRM`` order).

    Complements (1 - alpha, 1 - c_s, 1 - c_m) are formed in float64 first, as
    :func:`dstenv.dst.inputs.sensor_masses` does, so the kernel's input masses are
    the reference's to the bit.
    """
    values = {
        "alpha": params.alpha,
        "keep": 1.0 - params.alpha,
        "dinc": params.delta_inc,
        "ddec": params.delta_dec,
        "g_occ": params.gamma_occupied,
        "g_conf": params.gamma_conflict,
        "cs": params.sensor_confidence,
        "ncs": 1.0 - params.sensor_confidence,
        "cm": params.map_confidence,
        "ncm": 1.0 - params.map_confidence,
    }
    return np.array([values[name] for name in PRM], dtype=np.float32)


def plane_grid(channels: int, shape: tuple[int, int]) -> np.ndarray:
    """A zeroed ``(channels, P) float32`` plane array for an ``(H, W)`` grid (module docstring).

    ``P`` is ``H * W + W`` rounded up to whole cache lines, plus one more line: with
    power-of-two grids a plane of 2^k bytes would map the same cell of every plane
    onto the same L1 set, and the loop reads and writes ~40 planes at once.
    """
    h, w = shape
    p = -(-(h * w + w) // 16) * 16 + 16
    return np.zeros((channels, p), np.float32)


def grid_view(planes: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """The ``(C, H, W)`` view of a :func:`plane_grid` array (no copy, not C-contiguous)."""
    h, w = shape
    return planes[:, : h * w].reshape(planes.shape[0], h, w)


def history_rows(geo: np.ndarray, shape: tuple[int, int]) -> tuple[int, bool]:
    """Row order and history ring of :func:`inplace_update` for one motion.

    Cell ``(i, j)`` reads the previous cell ``si = floor(e(i, j) + 0.5)`` with ``e``
    affine in ``(i, j)`` (``row_sources``), so ``i - si`` is at most
    ``floor(0.5 - min(e - i))`` over the four corners. Rows are updated in the order
    whose sources lie mostly ahead (not yet overwritten); the ring keeps the
    original of as many overwritten rows as a source can lag behind (0 for a pure
    translation along the rows' order, ~W/2 sin(dyaw) rows for a turn).

    Args:
        geo: ``(5,) float64`` ``(cos dyaw, sin dyaw, dx [m], dy [m], cell [m])``.
        shape: ``(H, W)``.

    Returns:
        ``(k_hist, desc)``: rows in the ring, and whether rows run from H - 1 down to 0.
    """
    ct, st, dx, _, cell = (float(v) for v in geo)
    h, w = shape
    i0, j0 = h // 2, w // 2
    lag = [i0 - (ct * (i0 - i) - st * (j0 - j)) - dx / cell - i
           for i in (0, h - 1) for j in (0, w - 1)]  # e - i at the corners
    eps = 1e-6  # float64 rounding of row_sources' formula
    behind = max(0, math.floor(0.5 - min(lag) + eps))  # ascending: max(i - si)
    ahead = max(0, math.floor(0.5 + max(lag) + eps))  # descending: max(si - i)
    # a source more than H - 1 rows away is outside the grid (the vacuous pad): the ring
    # never needs more than H rows (a (1, 100000) grid turning asked for 29.7 GiB)
    return (min(ahead, h), True) if ahead < behind else (min(behind, h), False)
