"""Dempster-Shafer perception-grid engine (pure numpy + numba, no gymnasium).

Mass grids are ``(..., 32, H, W) float32`` indexed by subset bitmask over
(N=1, W=2, I=4, S=8, M=16); see :mod:`dstenv.dst.frame`. The update follows
``dst-spec.md``; :mod:`dstenv.dst.reference` states it plainly and
:class:`PerceptionGridFilter` runs it fast.
"""

from dstenv.dst.filter import PerceptionGridFilter
from dstenv.dst.frame import (
    CLASSES,
    EMPTY,
    FREE,
    NUM_CLASSES,
    NUM_SETS,
    OCCUPIED,
    OMEGA,
    I,
    M,
    N,
    S,
    SensorState,
    W,
    subset_name,
)
from dstenv.dst.inputs import map_masses, sensor_masses
from dstenv.dst.params import DSTParams
from dstenv.dst.rules import (
    conjunctive,
    dempster,
    discount,
    mass_within,
    modified_conjunctive,
    pignistic,
    specialise,
    vacuous,
)

__all__ = [
    "CLASSES", "NUM_CLASSES", "NUM_SETS", "EMPTY", "FREE", "OCCUPIED", "OMEGA",
    "N", "W", "I", "S", "M", "SensorState", "subset_name",
    "conjunctive", "dempster", "modified_conjunctive", "discount", "specialise",
    "mass_within", "pignistic", "vacuous", "sensor_masses", "map_masses",
    "DSTParams", "PerceptionGridFilter",
]
