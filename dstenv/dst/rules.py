"""Combination rules and transforms on mass grids, in plain (vectorised) numpy.

Every function takes mass grids ``(..., 32, H, W)`` (any leading batch axes; the
set axis is third from last) and returns a new float32 array of the same layout.
Products are accumulated in float64 and only the focal sets actually present are
visited, so the cost follows the number of focal elements, not 32 x 32.
"""

from __future__ import annotations

import numpy as np

from dstenv.dst.frame import (
    CARDINALITY, EMPTY, FREE, M, NUM_CLASSES, NUM_SETS, OCCUPIED, OMEGA, subsets_of,
)

__all__ = [
    "vacuous",
    "conjunctive",
    "dempster",
    "modified_conjunctive",
    "discount",
    "specialise",
    "mass_within",
    "pignistic",
]

SET_AXIS = -3


def _check(m: np.ndarray, name: str = "m") -> np.ndarray:
    """``m`` as an array of mass functions: shape ``(..., 32, H, W)``, finite, >= 0 and
    summing to 1 per cell (to 1e-3; the empty set included)."""
    m = np.asarray(m)
    if m.ndim < 3 or m.shape[SET_AXIS] != NUM_SETS:
        raise ValueError(f"{name} must have shape (..., 32, H, W), got {m.shape}")
    if not np.all(np.isfinite(m)) or m.min(initial=0.0) < -1e-6:
        raise ValueError(f"{name}: masses must be finite and >= 0")
    total = m.sum(axis=SET_AXIS, dtype=np.float64)
    if total.size and np.abs(total - 1.0).max() > 1e-3:
        raise ValueError(f"{name}: the masses of a cell must sum to 1, found sums in "
                         f"[{total.min():.4g}, {total.max():.4g}]")
    return m


def _focal(m: np.ndarray) -> list[int]:
    """Sets carrying mass somewhere in the grid."""
    axes = tuple(ax for ax in range(m.ndim) if ax != m.ndim + SET_AXIS)
    present = np.any(m != 0, axis=axes)
    return [int(a) for a in np.flatnonzero(present)]


def vacuous(shape: tuple[int, int], batch: tuple[int, ...] = ()) -> np.ndarray:
    """Total ignorance, m(Omega) = 1 everywhere: ``(*batch, 32, H, W) float32``."""
    m = np.zeros((*batch, NUM_SETS, *shape), dtype=np.float32)
    m[..., OMEGA, :, :] = 1.0
    return m


def _combine(m1: np.ndarray, m2: np.ndarray, route) -> np.ndarray:
    m1, m2 = _check(m1, "m1"), _check(m2, "m2")
    shape = np.broadcast_shapes(m1.shape, m2.shape)
    out = np.zeros(shape, dtype=np.float64)
    f2 = _focal(m2)
    for b in _focal(m1):
        mb = m1[..., b, :, :].astype(np.float64)
        for c in f2:
            out[..., route(b, c), :, :] += mb * m2[..., c, :, :]
    return out


def conjunctive(m1: np.ndarray, m2: np.ndarray) -> np.ndarray:
    """Unnormalised conjunctive combination: (m1 & m2)(A) = sum over B & C = A of m1(B) m2(C).

    The conflict stays on the empty set (index 0).

    Args:
        m1, m2: ``(..., 32, H, W)`` mass grids (broadcastable).

    Returns:
        ``(..., 32, H, W) float32``.
    """
    return _combine(m1, m2, lambda b, c: b & c).astype(np.float32)


def dempster(m1: np.ndarray, m2: np.ndarray) -> np.ndarray:
    """Dempster's rule: conjunctive combination, conflict K removed and the rest divided by 1 - K.

    Where the conflict is total (K == 1) the result is vacuous.

    Args:
        m1, m2: ``(..., 32, H, W)`` mass grids.

    Returns:
        ``(..., 32, H, W) float32`` with ``m[0] == 0``.
    """
    out = _combine(m1, m2, lambda b, c: b & c)
    k = out[..., EMPTY, :, :].copy()
    out[..., EMPTY, :, :] = 0.0
    total = k >= 1.0 - 1e-12
    out /= np.where(total, 1.0, 1.0 - k)[..., None, :, :]
    out[..., OMEGA, :, :] += total
    return out.astype(np.float32)


def _temporal_route(b: int, c: int) -> int:
    inter = b & c
    if inter:
        return inter
    if b & ~FREE == 0 and c & ~OCCUPIED == 0:
        return M  # free became occupied: moving
    return OMEGA  # occupied became free, or any other conflict (Yager)


def modified_conjunctive(m_past: np.ndarray, m_new: np.ndarray) -> np.ndarray:
    """The temporal rule of the spec (step 7): conflict F->O goes to {M}, every other to Omega.

    Args:
        m_past: ``(..., 32, H, W)`` discounted, specialised past grid.
        m_new: ``(..., 32, H, W)`` current sensor-and-map grid.

    Returns:
        ``(..., 32, H, W) float32``, summing to 1 without normalisation.
    """
    return _combine(m_past, m_new, _temporal_route).astype(np.float32)


def discount(m: np.ndarray, alpha: float | np.ndarray) -> np.ndarray:
    """Discounting at rate alpha: m(A) <- (1 - alpha) m(A), and alpha added to Omega.

    Args:
        m: ``(..., 32, H, W)`` mass grid.
        alpha: scalar or array broadcastable to ``(..., H, W)``, in [0, 1].

    Returns:
        ``(..., 32, H, W) float32``.
    """
    m = _check(m)
    a = np.asarray(alpha, dtype=np.float64)
    if not (a.size and np.all((a >= 0.0) & (a <= 1.0))):  # NaN fails too
        raise ValueError(f"discount: alpha must lie in [0, 1], got {alpha!r}")
    cells = (*m.shape[:-3], *m.shape[-2:])
    try:
        fits = not a.ndim or np.broadcast_shapes(a.shape, cells) == cells
    except ValueError:
        fits = False
    if not fits:
        raise ValueError(f"discount: alpha of shape {a.shape} does not fit the cells {cells}")
    out = m.astype(np.float64) * (1.0 - a)[..., None, :, :] if a.ndim else m * (1.0 - a)
    out = np.array(out, dtype=np.float64)
    out[..., OMEGA, :, :] += a
    return out.astype(np.float32)


def specialise(m: np.ndarray, zeta: np.ndarray) -> np.ndarray:
    """Move a fraction zeta of every m(A), A containing M and something else, to A minus {M}.

    Sets without M, and {M} itself, are unchanged (spec step 5).

    Args:
        m: ``(..., 32, H, W)`` mass grid.
        zeta: ``(..., H, W)`` accumulator in [0, 1].

    Returns:
        ``(..., 32, H, W) float32``.
    """
    m = _check(m)
    z = np.asarray(zeta, dtype=np.float64)
    if not np.all((z >= 0.0) & (z <= 1.0)):  # NaN fails too
        raise ValueError("specialise: zeta must lie in [0, 1]")
    out = m.astype(np.float64)
    for a in range(NUM_SETS):
        if a & M and a != M:
            moved = z * out[..., a, :, :]
            out[..., a & ~M, :, :] += moved
            out[..., a, :, :] -= moved
    return out.astype(np.float32)


def mass_within(m: np.ndarray, subset: int) -> np.ndarray:
    """Sum of m(A) over non-empty A contained in ``subset`` (e.g. m(F), m(O)).

    Returns:
        ``(..., H, W)`` in the input's precision.
    """
    m = _check(m)
    if not 0 < int(subset) < NUM_SETS:
        raise ValueError(f"mass_within: subset must be a set index in 1..{NUM_SETS - 1}, "
                         f"got {subset}")
    return m[..., subsets_of(subset), :, :].sum(axis=SET_AXIS)


def pignistic(m: np.ndarray) -> np.ndarray:
    """Pignistic probability BetP(x) = sum over A containing x of m(A) / |A| / (1 - m(empty)).

    Args:
        m: ``(..., 32, H, W)`` mass grid (m(empty) = 0 after Dempster's rule; a
            conjunctive result's conflict is divided out, Smets' normalisation).

    Returns:
        ``(..., 5, H, W) float32`` over ``CLASSES``, summing to 1 per cell.

    Raises:
        ValueError: masses that are not mass functions, or total conflict somewhere.
    """
    m = _check(m)
    out = np.zeros((*m.shape[:-3], NUM_CLASSES, *m.shape[-2:]), dtype=np.float64)
    for a in _focal(m):
        if a == EMPTY:
            continue
        ma = m[..., a, :, :]
        for x in range(NUM_CLASSES):
            if a >> x & 1:
                out[..., x, :, :] += ma / CARDINALITY[a]
    conflict = m[..., EMPTY, :, :].astype(np.float64)
    if conflict.any():  # only then: m(empty) = 0 keeps the bits of the plain sum
        if (conflict >= 1.0 - 1e-12).any():
            raise ValueError("pignistic: total conflict (m(empty) = 1) in some cell")
        out /= (1.0 - conflict)[..., None, :, :]
    return out.astype(np.float32)
