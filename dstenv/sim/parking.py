"""Kerbside parking of the procedural city: where parked vehicles stand, and which.

Two layouts (``world.map.parking_layout``):

* ``"lattice"``: the ideal world of the ``clean`` scenario: slots exactly
  :data:`SLOT_LENGTH` apart, centred in the kerb strip, aligned with the kerb; the
  vehicle size is drawn later by the spawner (one car size).
* ``"irregular"``: vehicles placed one after the other along the kerb with a drawn
  gap between them, a vehicle class from ``parking_mix`` (small car, car, van,
  truck), a lateral offset per street side plus one per vehicle, a heading error per
  vehicle, and now and then a car parked half on the sidewalk. Empty stretches come
  from ``traffic.parked_density`` (a slot is occupied with that probability).

Every slot is a row ``(x, y, yaw, length, width, height)`` [m, rad]; ``length = 0``
(lattice) lets the spawner draw a car size.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["SLOT_LENGTH", "VEHICLE_CLASSES", "CLASS_LO", "CLASS_HI", "side_slots", "draw_vehicles"]

SLOT_LENGTH = 6.0  # [m] length of one kerbside parking slot (lattice layout)

#: vehicle classes of ``parking_mix`` / ``traffic.vehicle_mix``: name -> (length range,
#: width range, height range) [m]
VEHICLE_CLASSES: dict[str, tuple[tuple[float, float], tuple[float, float], tuple[float, float]]] = {
    "small": ((3.4, 3.9), (1.6, 1.72), (1.4, 1.55)),
    "car": ((4.0, 4.9), (1.72, 1.95), (1.4, 1.65)),
    "van": ((4.9, 6.2), (1.9, 2.1), (2.0, 2.6)),
    "truck": ((6.5, 8.5), (2.3, 2.5), (3.0, 3.5)),
}
_NAMES = tuple(VEHICLE_CLASSES)
#: ``(4, 3)`` lower and upper bounds of length, width, height per class [m]
CLASS_LO = np.array([[VEHICLE_CLASSES[k][d][0] for d in range(3)] for k in _NAMES])
CLASS_HI = np.array([[VEHICLE_CLASSES[k][d][1] for d in range(3)] for k in _NAMES])


def draw_vehicles(mix: list[float] | tuple[float, ...], n: int,
                  rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Vehicle classes and sizes from a mix.

    Args:
        mix: ``(4,)`` non-negative weights of small car, car, van, truck.
        n: number of vehicles.

    Returns:
        ``cls (n,) int64`` index into :data:`VEHICLE_CLASSES` and ``size (n, 3)
        float64`` length, width, height [m].
    """
    p = np.asarray(mix, np.float64)
    cls = rng.choice(len(_NAMES), size=n, p=p / p.sum())
    size = CLASS_LO[cls] + rng.random((n, 3)) * (CLASS_HI[cls] - CLASS_LO[cls])
    return cls, size


def side_slots(start: np.ndarray, along: np.ndarray, inward: np.ndarray, length: float,
               cfg: dict[str, Any], rng: np.random.Generator, avoid: np.ndarray
               ) -> np.ndarray:
    """Parking positions along one block side.

    Args:
        start, along, inward: the side's kerb start point, unit direction along the
            kerb and unit normal into the block (world frame).
        length: kerb length [m].
        cfg: the ``world.map`` section.
        avoid: ``(K, 2)`` crosswalk ends; no vehicle stands across them.

    Returns:
        ``(S, 6) float64`` rows ``x, y, yaw, length, width, height`` (see module doc).
    """
    curb, sw = cfg["curb_strip_width"], cfg["sidewalk_width"]
    keep_clear = curb + sw + 10.0  # [m] no parking near junctions (crosswalks, turns)
    yaw = float(np.arctan2(-along[1], -along[0]))  # with the adjacent traffic (right-hand)
    if cfg["parking_layout"] == "lattice":
        n = int((length - 2 * keep_clear) // SLOT_LENGTH)
        if n < 1:
            return np.zeros((0, 6))
        s0 = (length - n * SLOT_LENGTH) / 2
        s = s0 + (np.arange(n) + 0.5) * SLOT_LENGTH
        lat = np.full(n, curb / 2)
        heading = np.full(n, yaw)
        size = np.zeros((n, 3))
        clear = np.full(n, SLOT_LENGTH / 2)
    else:
        room = length - keep_clear
        # enough vehicles and gaps for the side, drawn at once; the ones that fit are kept
        m = max(int((room - keep_clear) / 4.0) + 1, 1)
        _, size = draw_vehicles(cfg["parking_mix"], m, rng)
        gap = rng.uniform(cfg["parking_gap_min"], cfg["parking_gap_max"], m)
        first = keep_clear + rng.uniform(0.0, cfg["parking_gap_max"])
        ends = first + np.cumsum(size[:, 0] + gap) - gap  # rear end of vehicle k + its length
        n = int(np.searchsorted(ends, room, side="right"))
        if n == 0:
            return np.zeros((0, 6))
        size = size[:n]
        s = ends[:n] - size[:, 0] / 2
        jit = cfg["parking_lateral_jitter"]
        lat = curb / 2 + rng.uniform(-jit, jit) + rng.normal(0.0, jit / 2, n)
        # the wheels stay in the strip: a wide vehicle is not pushed off the kerb line
        lat = np.clip(lat, size[:, 1] / 2 - 0.1, np.maximum(curb - size[:, 1] / 2 + 0.1,
                                                           size[:, 1] / 2 - 0.1))
        half_on = (rng.random(n) < cfg["half_on_sidewalk_prob"]) & (size[:, 0] < 5.0) & (sw > 1.8)
        lat[half_on] = curb + rng.uniform(-0.2, 0.1, int(half_on.sum()))
        heading = yaw + np.deg2rad(cfg["parking_heading_jitter"]) * rng.standard_normal(n)
        clear = size[:, 0] / 2
    centres = start + along * s[:, None] + inward * lat[:, None]
    if len(avoid):
        need = clear + curb + sw  # [m] least distance of each vehicle to a crosswalk end
        # only the ends within reach of the side matter (a city has thousands)
        lo, hi = centres.min(0) - need.max(), centres.max(0) + need.max()
        avoid = avoid[(avoid[:, 0] >= lo[0]) & (avoid[:, 0] <= hi[0]) &
                      (avoid[:, 1] >= lo[1]) & (avoid[:, 1] <= hi[1])]
    if len(avoid):
        near = np.hypot(avoid[None, :, 0] - centres[:, None, 0],
                        avoid[None, :, 1] - centres[:, None, 1]).min(1)
        ok = near >= need
        centres, heading, size = centres[ok], heading[ok], size[ok]
    return np.column_stack([centres, heading, size]).reshape(-1, 6)
