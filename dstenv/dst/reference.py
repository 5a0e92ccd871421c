"""The DST update written plainly from the spec, dense over all 32 sets.

This is the executable statement of ``dst-spec.md`` steps 1-8: slow and obvious.
:class:`dstenv.dst.PerceptionGridFilter` must agree with it (tests compare them),
and ``dstenv bench fusion`` measures the fast filter against it.
"""

from __future__ import annotations

import numpy as np

from dstenv.dst.frame import FREE, NUM_SETS, OCCUPIED, OMEGA
from dstenv.dst.inputs import map_masses, sensor_masses
from dstenv.dst.params import DSTParams
from dstenv.dst.rules import dempster, discount, mass_within, modified_conjunctive, specialise

__all__ = ["source_cells", "warp", "reference_update"]


def source_cells(
    shape: tuple[int, int], cell_size: float, ego_motion: tuple[float, float, float]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For every current cell, the previous-frame cell it comes from (nearest neighbour).

    A current cell centre ``p`` (ego frame at t, see :mod:`dstenv.grid`) lies at
    ``R(dyaw) p + (dx, dy)`` in the previous ego frame.

    Args:
        shape: ``(H, W)``.
        cell_size: [m].
        ego_motion: ``(dx [m], dy [m], dyaw [rad])``, the current pose in the previous
            ego frame (:func:`dstenv.grid.relative_pose`).

    Returns:
        ``(si, sj, valid)``: ``(H, W) int64`` source rows and columns, and a
        ``(H, W) bool`` mask of sources inside the previous grid.
    """
    h, w = shape
    i0, j0 = h // 2, w // 2
    dx, dy, dyaw = (float(v) for v in ego_motion)
    ct, st = np.cos(dyaw), np.sin(dyaw)
    inv = 1.0 / cell_size
    x = ((i0 - np.arange(h)) * cell_size)[:, None]
    y = ((j0 - np.arange(w)) * cell_size)[None, :]
    si = np.floor(i0 - (ct * x - st * y + dx) * inv + 0.5).astype(np.int64)
    sj = np.floor(j0 - (st * x + ct * y + dy) * inv + 0.5).astype(np.int64)
    valid = (si >= 0) & (si < h) & (sj >= 0) & (sj < w)
    return si, sj, valid


def warp(
    masses: np.ndarray, zeta: np.ndarray, cell_size: float, ego_motion: tuple[float, float, float]
) -> tuple[np.ndarray, np.ndarray]:
    """Spec step 1: move the previous grid into the current ego frame.

    Args:
        masses: ``(32, H, W)`` previous grid; zeta: ``(H, W)`` previous accumulator.

    Returns:
        ``(masses, zeta)`` in the current frame; cells from outside are vacuous, zeta 0.
    """
    si, sj, valid = source_cells(zeta.shape, cell_size, ego_motion)
    si, sj = np.clip(si, 0, zeta.shape[0] - 1), np.clip(sj, 0, zeta.shape[1] - 1)
    m = np.where(valid[None], masses[:, si, sj], 0.0).astype(np.float32)
    m[OMEGA][~valid] = 1.0
    return m, np.where(valid, zeta[si, sj], 0.0).astype(np.float32)


def reference_update(
    masses: np.ndarray,
    zeta: np.ndarray,
    sensor_states: np.ndarray,
    map_classes: np.ndarray,
    params: DSTParams,
    cell_size: float = 0.33,
    ego_motion: tuple[float, float, float] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """One perception-grid update (spec steps 1-8), dense numpy.

    Args:
        masses: ``(32, H, W) float32`` previous perception grid.
        zeta: ``(H, W) float32`` previous accumulator.
        sensor_states: ``(H, W) uint8`` 0 unknown / 1 free / 2 occupied.
        map_classes: ``(H, W) uint8`` 0 none / 1 building / 2 road / 3 intermediate.
        params: the update's numbers.
        cell_size: [m], used by the ego motion.
        ego_motion: ``(dx, dy, dyaw)`` or ``None`` for a static ego.

    Returns:
        ``(masses (32, H, W) float32, zeta (H, W) float32)`` at t.
    """
    assert masses.shape[0] == NUM_SETS
    if ego_motion is not None:
        masses, zeta = warp(masses, zeta, cell_size, ego_motion)
    m_sm = dempster(
        sensor_masses(sensor_states, params.sensor_confidence),
        map_masses(map_classes, params.map_confidence),
    )
    c_fo = mass_within(masses, FREE) * mass_within(m_sm, OCCUPIED)
    c_of = mass_within(masses, OCCUPIED) * mass_within(m_sm, FREE)
    conflict = c_fo + c_of
    inc = (mass_within(masses, OCCUPIED) >= params.gamma_occupied) & (
        conflict <= params.gamma_conflict
    )
    dec = conflict > params.gamma_conflict
    zeta = np.where(inc, np.minimum(1.0, zeta + params.delta_inc), zeta)
    zeta = np.where(dec, np.maximum(0.0, zeta - params.delta_dec), zeta).astype(np.float32)
    past = discount(specialise(masses, zeta), params.alpha)
    return modified_conjunctive(past, m_sm), zeta
