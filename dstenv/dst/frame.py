"""The frame of discernment and the storage layout of mass grids.

Five singletons, each one bit of a subset's index (``dst-spec.md``):

=====  =====  ======  =================
 bit   value  symbol  class (label index)
=====  =====  ======  =================
  0      1      N     navigable (0)
  1      2      W     non_navigable (1)
  2      4      I     building (2)
  3      8      S     static (3)
  4     16      M     moving (4)
=====  =====  ======  =================

A mass function on a cell is 32 floats indexed by the subset's bitmask (index 0 is
the empty set, 31 is Omega); a grid of them is ``(32, H, W) float32``, a batch
``(..., 32, H, W)``. Label grids use the class indices 0..4 in the same order.
"""

from __future__ import annotations

from enum import IntEnum

import numpy as np

__all__ = [
    "CLASSES",
    "NUM_CLASSES",
    "NUM_SETS",
    "N", "W", "I", "S", "M",
    "FREE", "OCCUPIED", "OMEGA", "EMPTY",
    "SensorState",
    "CARDINALITY",
    "subset_name",
    "subsets_of",
]

CLASSES: tuple[str, ...] = ("navigable", "non_navigable", "building", "static", "moving")
NUM_CLASSES: int = len(CLASSES)
NUM_SETS: int = 1 << NUM_CLASSES  # 32

N, W, I, S, M = 1, 2, 4, 8, 16
EMPTY: int = 0
FREE: int = N | W  # 3
OCCUPIED: int = I | S | M  # 28
OMEGA: int = NUM_SETS - 1  # 31


class SensorState(IntEnum):
    """Codes of a sensor grid (``(H, W) uint8``), as produced by LIDAR ray casting."""

    UNKNOWN = 0
    FREE = 1
    OCCUPIED = 2


#: ``(32,) int64``: number of singletons in each subset.
CARDINALITY: np.ndarray = np.array([bin(a).count("1") for a in range(NUM_SETS)], dtype=np.int64)

_SYMBOLS = "NWISM"


def subset_name(index: int) -> str:
    """Readable name of a subset, e.g. ``subset_name(25) == "{N,S,M}"``."""
    if index == OMEGA:
        return "Omega"
    if index == EMPTY:
        return "{}"
    return "{" + ",".join(s for b, s in enumerate(_SYMBOLS) if index >> b & 1) + "}"


def subsets_of(mask: int) -> np.ndarray:
    """Indices of the non-empty subsets contained in ``mask``: ``(K,) int64``."""
    return np.array([a for a in range(1, NUM_SETS) if a & ~mask == 0], dtype=np.int64)
