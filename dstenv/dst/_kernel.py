"""Run-time tables and buffers for the fused update kernel in ``_fused.py``.

Only 15 of the 32 subsets can ever carry mass in a filter state (the intersection
closure of the sensor-and-map focal sets, their specialisations and {M});
:mod:`dstenv.dst._codegen` derives them and writes the unrolled kernel.
"""

from __future__ import annotations

import numpy as np

from dstenv.dst._codegen import SM_CASES
from dstenv.dst._fused import REACHABLE, fused_update
from dstenv.dst.frame import FREE, NUM_SETS, OCCUPIED
from dstenv.dst.inputs import map_masses, sensor_masses
from dstenv.dst.params import DSTParams
from dstenv.dst.rules import dempster

__all__ = ["REACHABLE", "sensor_map_weights", "padded_grid", "fused_update"]

_MAX_FOCAL = max(len(cs) for _, _, cs in SM_CASES)


def sensor_map_weights(params: DSTParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """m_sm = dempster(sensor, map) for each of the 3 x 4 input cases, as kernel tables.

    Returns:
        ``(wsm, sm_free, sm_occ)``: ``(12, K) float64`` masses of each case's focal
        sets (in ``_fused.CASE_SETS`` order), and ``(12,) float64`` m_sm(F), m_sm(O).
        Case index = 4 * sensor code + map code.
    """
    n = len(SM_CASES)
    sensor = np.array([[s for s, _, _ in SM_CASES]], dtype=np.uint8)
    gis = np.array([[g for _, g, _ in SM_CASES]], dtype=np.uint8)
    m = dempster(
        sensor_masses(sensor, params.sensor_confidence), map_masses(gis, params.map_confidence)
    ).astype(np.float64)[:, 0, :]  # (32, 12)
    wsm = np.zeros((n, _MAX_FOCAL))
    for idx, (s, g, sets) in enumerate(SM_CASES):
        if idx != 4 * s + g:
            raise AssertionError("SM_CASES must be ordered by 4 * sensor + map")
        carried = set(np.flatnonzero(m[:, idx]).tolist())
        if not carried <= set(sets):
            raise AssertionError(f"case {idx} puts mass outside its generated focal sets")
        wsm[idx, : len(sets)] = m[sets, idx]
    free = [a for a in range(1, NUM_SETS) if a & ~FREE == 0]
    occ = [a for a in range(1, NUM_SETS) if a & ~OCCUPIED == 0]
    return wsm, m[free].sum(0), m[occ].sum(0)


def padded_grid(channels: int, shape: tuple[int, int]) -> np.ndarray:
    """A zeroed ``(channels, H, W) float32`` view whose channel stride is not a power of two.

    Channel planes of 2^k bytes map the same cell of every plane onto the same cache
    set; 64 spare floats per plane avoid that aliasing in the per-cell kernel.
    """
    h, w = shape
    base = np.zeros((channels, h * w + 64), np.float32)
    return base[:, : h * w].reshape(channels, h, w)
