"""Sensor and map evidence as mass grids (spec: "Inputs per cell")."""

from __future__ import annotations

import numpy as np

from dstenv.dst.frame import FREE, I, M, N, NUM_SETS, OCCUPIED, OMEGA, S, W, SensorState

__all__ = ["sensor_masses", "map_masses", "SENSOR_SETS", "MAP_SETS"]

#: sensor state code -> focal set it supports (UNKNOWN supports nothing but Omega).
SENSOR_SETS: dict[int, int] = {
    SensorState.UNKNOWN: OMEGA,
    SensorState.FREE: FREE,
    SensorState.OCCUPIED: OCCUPIED,
}
#: map class code (``dstenv.sim.types.MapClass``) -> refined set in the PG frame.
MAP_SETS: dict[int, int] = {0: OMEGA, 1: I, 2: N | S | M, 3: W | S | M}


def _masses(codes: np.ndarray, table: dict[int, int], confidence: float, what: str) -> np.ndarray:
    codes = np.asarray(codes)
    if codes.ndim != 2:
        raise ValueError(f"{what} must be a (H, W) grid, got shape {codes.shape}")
    if not 0.0 <= confidence <= 1.0:
        raise ValueError(f"confidence must lie in [0, 1], got {confidence}")
    bad = ~np.isin(codes, list(table))
    if bad.any():
        raise ValueError(
            f"{what} holds unknown code {int(codes[bad][0])}; allowed codes: {sorted(table)}"
        )
    out = np.zeros((NUM_SETS, *codes.shape), dtype=np.float32)
    out[OMEGA] = 1.0
    for code, subset in table.items():
        if subset == OMEGA:
            continue
        sel = codes == code
        out[subset][sel] = confidence
        out[OMEGA][sel] = 1.0 - confidence
    return out


def sensor_masses(states: np.ndarray, confidence: float = 0.8) -> np.ndarray:
    """Mass grid of a sensor grid.

    Args:
        states: ``(H, W) uint8`` codes: 0 unknown, 1 free, 2 occupied.
        confidence: c_s, mass on F = {N, W} (free) or O = {I, S, M} (occupied).

    Returns:
        ``(32, H, W) float32``; unknown cells are vacuous.
    """
    return _masses(states, SENSOR_SETS, confidence, "sensor states")


def map_masses(classes: np.ndarray, confidence: float = 0.995) -> np.ndarray:
    """Mass grid of a GIS grid, refined to the perception-grid frame.

    Args:
        classes: ``(H, W) uint8`` codes: 0 no information, 1 building -> {I},
            2 road -> {N, S, M}, 3 intermediate -> {W, S, M}.
        confidence: c_m, mass on the refined set; the rest goes to Omega.

    Returns:
        ``(32, H, W) float32``; cells without information are vacuous.
    """
    return _masses(classes, MAP_SETS, confidence, "map classes")
