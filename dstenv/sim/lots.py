"""Off-street parking lots of the procedural city (``world.map.lot_prob``).

Kerbside strips (:mod:`dstenv.sim.parking`) put every parked car within a few metres
of a driving lane. Real drives also pass open lots and squares where rows of cars
stand 10-30 m from the road, seen across open ground (KITTI 0003's two parked cars
stand ~20 m to the side of the ego's road). A lot replaces the buildings along one
side of a block: behind the sidewalk, ``lot_depth`` metres deep and clear of the
block's corners, rows of stalls either perpendicular to the street (back-to-back
pairs of 5 m rows with 6.5 m aisles) or parallel to it (2 m rows, 5 m aisles), each
stall holding a car with probability ``lot_fill``.

Every lot car is a slot row ``(x, y, yaw, length, width, height)`` [m, rad] like the
kerbside ones, sized here (small cars and cars of ``parking.VEHICLE_CLASSES``); the
spawner parks a vehicle in every slot. The lots draw from their own generator, so a
city with ``lot_prob = 0`` is the one it was before lots existed.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from dstenv.sim.parking import VEHICLE_CLASSES

__all__ = ["city_lots", "clear_of_lots"]

_END = 10.0  # [m] lot kept clear of each end of the block side (corners, junctions)
_STALL_W = 2.6  # [m] width of a perpendicular stall
_PERP_ROW, _PERP_AISLE = 5.0, 6.5  # [m] depth of a perpendicular row, aisle between pairs
_PAR_ROW, _PAR_AISLE, _PAR_PITCH = 2.0, 5.0, 6.2  # [m] parallel row, aisle, stall length
_CLEAR = 3.0  # [m] a car's centre this far from an earlier lot of its block


def _overlaps(b: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> bool:
    """Whether the bounding box of polygon ``b`` ``(4, 2)`` meets the box ``[lo, hi]``."""
    return bool((b.max(0) > lo).all() and (b.min(0) < hi).all())


def _rows(depth: float, perpendicular: bool) -> list[float]:
    """Inward offsets of the row centres from the lot's street edge [m]."""
    out: list[float] = []
    if perpendicular:
        base = 0.0
        while base + 2 * _PERP_ROW <= depth:
            out += [base + _PERP_ROW / 2, base + 1.5 * _PERP_ROW]
            base += 2 * _PERP_ROW + _PERP_AISLE
        if base + _PERP_ROW <= depth:
            out.append(base + _PERP_ROW / 2)
    else:
        base = 0.0
        while base + _PAR_ROW <= depth:
            out.append(base + _PAR_ROW / 2)
            base += _PAR_ROW + _PAR_AISLE
    return out


def city_lots(faces: list[tuple[float, float, float, float]], sides: list[list[tuple]],
              buildings: list[np.ndarray], cfg: dict[str, Any], rng: np.random.Generator
              ) -> tuple[list[int], np.ndarray, np.ndarray]:
    """Parking lots along block sides, in place of their buildings.

    Args:
        faces: blocks ``(x0, x1, y0, y1)`` [m] at the kerb.
        sides: per face, its four ``(start, along, inward, length)`` sides.
        buildings: the city's building polygons ``(4, 2)`` (not yet warped).
        cfg: the ``world.map`` section (``lot_prob``, ``lot_depth``, ``lot_fill``, kerb
            strip and sidewalk widths).
        rng: the lots' own generator.

    Returns:
        ``(kept, slots, rects)``: indices of the buildings that stay, ``(S, 6) float64``
        lot cars (module doc) and ``(R, 4) float64`` lot rectangles ``x_lo, x_hi, y_lo,
        y_hi`` [m].
    """
    front = float(cfg["curb_strip_width"] + cfg["sidewalk_width"]) + 1.0
    small, car = VEHICLE_CLASSES["small"], VEHICLE_CLASSES["car"]
    drop: set[int] = set()
    slots: list[tuple[float, ...]] = []
    rects: list[tuple[float, float, float, float]] = []
    for (x0, x1, y0, y1), four in zip(faces, sides, strict=True):
        across = (y1 - y0, x1 - x0, y1 - y0, x1 - x0)  # block size across each side
        first = len(rects)
        for k, (start, along, inward, length) in enumerate(four):
            if rng.random() >= cfg["lot_prob"]:
                continue
            depth = min(float(cfg["lot_depth"]), across[k] / 2 - front - 1.0)
            if length - 2 * _END < 3 * _STALL_W or depth < _PERP_ROW:
                continue
            perpendicular = bool(rng.random() < 0.5)
            a, b = start + along * _END + inward * front, start + along * (length - _END) \
                + inward * (front + depth)
            lo, hi = np.minimum(a, b), np.maximum(a, b)
            # the corner two lots of one block share is the first one's
            earlier = rects[first:]
            rects.append((lo[0], hi[0], lo[1], hi[1]))
            drop.update(i for i, poly in enumerate(buildings) if _overlaps(poly, lo, hi))
            street_yaw = float(np.arctan2(along[1], along[0]))
            pitch = _STALL_W if perpendicular else _PAR_PITCH
            n = int((length - 2 * _END) // pitch)
            for off in _rows(depth, perpendicular):
                for s in range(n):
                    if rng.random() >= cfg["lot_fill"]:
                        continue
                    cls = small if rng.random() < 0.3 else car
                    ln, wd, ht = (rng.uniform(*cls[d]) for d in range(3))
                    yaw = street_yaw + (np.pi / 2 if perpendicular else 0.0) \
                        + (np.pi if rng.random() < 0.5 else 0.0) + np.deg2rad(3.0) * rng.normal()
                    p = start + along * (_END + (s + 0.5) * pitch) + inward * (front + off)
                    if any(r[0] - _CLEAR < p[0] < r[1] + _CLEAR and r[2] - _CLEAR < p[1]
                           < r[3] + _CLEAR for r in earlier):
                        continue
                    slots.append((p[0], p[1], float(yaw), ln, wd, ht))
    kept = [i for i in range(len(buildings)) if i not in drop]
    return (kept, np.array(slots, np.float64).reshape(-1, 6),
            np.array(rects, np.float64).reshape(-1, 4))


def clear_of_lots(obstacles: Any, rects: np.ndarray) -> Any:
    """``obstacles`` (:class:`~dstenv.sim.types.Obstacles`) less the boxes that reach into
    a lot rectangle ``(R, 4)`` grown by 1 m (hedges and fences of the yards the lots
    replaced; a car's heading jitter carries its corners past the rectangle)."""
    from dataclasses import fields, replace

    if not len(obstacles) or not len(rects):
        return obstacles
    c = obstacles.corners()
    lo, hi = c.min(1), c.max(1)  # (K, 2)
    r = np.asarray(rects, np.float64) + np.array([-1.0, 1.0, -1.0, 1.0])  # cars' overhang
    meets = ((hi[:, None, 0] > r[None, :, 0]) & (lo[:, None, 0] < r[None, :, 1])
             & (hi[:, None, 1] > r[None, :, 2]) & (lo[:, None, 1] < r[None, :, 3])).any(1)
    keep = ~meets
    return replace(obstacles, **{f.name: getattr(obstacles, f.name)[keep]
                                 for f in fields(obstacles)})
