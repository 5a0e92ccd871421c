"""Rows of buildings along the sides of a block of the procedural city.

From the kerb in, a block has a kerb strip, a sidewalk, a setback, then a row of
buildings along each side: varied frontage and depth, gaps (alleys, driveways,
empty lots), none overlapping another. The rows of one block are placed by one
compiled loop that draws from the city's ``np.random.Generator`` itself (numba draws
from the generator's own bit stream in numpy's order and with numpy's algorithms),
in the order of the Python loop it replaces, so a seed gives the same buildings.
"""

from __future__ import annotations

from typing import Any

import numba as nb
import numpy as np

from dstenv.sim.parking import block_side

__all__ = ["block_buildings", "city_buildings"]


def block_buildings(face: tuple[float, float, float, float], cfg: dict[str, Any],
                    rng: np.random.Generator, side: int | None = None) -> list[np.ndarray]:
    """Rows of buildings along the four sides of a block (or only along ``side`` of a
    one-sided frontage strip), without overlaps: :func:`city_buildings` of one box."""
    return city_buildings([face], [-1 if side is None else side], cfg, rng)


def city_buildings(boxes: list[tuple[float, float, float, float]], sides: list[int],
                   cfg: dict[str, Any], rng: np.random.Generator) -> list[np.ndarray]:
    """Rows of buildings of a city's blocks and frontage strips, in one call.

    Args:
        boxes: blocks ``(x0, x1, y0, y1)`` [m] at the kerb.
        sides: per box, ``-1`` for a block (buildings along its four sides, in a
            drawn order) or ``0..3`` (bottom, right, top, left) for the street side of
            a one-sided frontage strip.
        cfg: the ``world.map`` section (kerb strip, sidewalk, setback, building and
            gap keys).
        rng: the city's generator. Draws, box after box (none for a box too small
            for buildings): for a block a permutation of its 4 sides; per side a
            setback, then per building slot its width, depth, setback offset, a
            coverage uniform and a gap uniform (and the gap when there is one).

    Returns:
        One ``(4, 2) float64`` rectangle [m] per building, counter-clockwise from
        its lowest x / lowest y corner, box after box.
    """
    front = cfg["curb_strip_width"] + cfg["sidewalk_width"] + 0.3  # clear of the walkers
    params = np.array([cfg[k] for k in ("building_width_min", "building_width_max",
                                        "building_depth_min", "building_depth_max",
                                        "building_coverage", "gap_prob", "gap_min", "gap_max",
                                        "setback_min", "setback_max")] + [front], np.float64)
    boxes = _city(rng, np.asarray(boxes, np.float64).reshape(-1, 4),
                  np.asarray(sides, np.int64), params)
    corners = np.stack([boxes[:, [0, 2]], boxes[:, [1, 2]], boxes[:, [1, 3]], boxes[:, [0, 3]]],
                       1)
    return list(corners)


@nb.njit(cache=True)
def _city(rng, faces, sides, params):  # pragma: no cover - numba
    """:func:`city_buildings`: ``(B, 4)`` boxes ``x_lo, x_hi, y_lo, y_hi`` of all boxes."""
    front = params[10]
    out = np.empty((1024, 4))
    n = 0
    inner = np.empty(4)
    one = np.empty(1, np.int64)
    for b in range(faces.shape[0]):
        side = sides[b]
        if side < 0:
            inner[0], inner[1] = faces[b, 0] + front, faces[b, 1] - front
            inner[2], inner[3] = faces[b, 2] + front, faces[b, 3] - front
        else:  # only the street side has a sidewalk
            near = (2, 1, 3, 0)[side]
            for k in range(4):
                inner[k] = faces[b, k]
                if k == near:
                    inner[k] = faces[b, k] + (front if k in (0, 2) else -front)
        if inner[1] - inner[0] < 4 or inner[3] - inner[2] < 4:
            continue
        if side < 0:
            order = rng.permutation(4)
        else:
            one[0] = side
            order = one
        got = _rows(rng, inner, order, params, side < 0)
        while n + got.shape[0] > out.shape[0]:
            grown = np.empty((2 * out.shape[0], 4))
            grown[:n] = out[:n]
            out = grown
        out[n:n + got.shape[0]] = got
        n += got.shape[0]
    return out[:n].copy()


@nb.njit(cache=True)
def _rows(rng, inner, order, params, block):  # pragma: no cover - numba
    """``(B, 4) float64`` building boxes ``x_lo, x_hi, y_lo, y_hi`` [m] along the sides
    ``order`` of the box ``inner``, in placement order. Scalar arithmetic in the order of
    the vector expressions ``start + along * pos + inward * setback``: the same bits."""
    w_min, w_max, d_min, d_max = params[0], params[1], params[2], params[3]
    coverage, gap_prob, gap_min, gap_max = params[4], params[5], params[6], params[7]
    sb_min, sb_max = params[8], params[9]
    x0, x1, y0, y1 = inner[0], inner[1], inner[2], inner[3]
    boxes = np.empty((64, 4))
    n = 0
    for si in order:
        # start, direction along and inward normal of side si (as _sides of citygen)
        sx, sy, ax, ay, ix, iy, length = block_side(x0, x1, y0, y1, si)
        depth_room = (y1 - y0) if ax != 0 else (x1 - x0)
        setback = rng.uniform(sb_min, sb_max)
        room = depth_room / 2 - setback if block else depth_room - setback - 2.0
        pos = 0.0
        while pos < length - w_min:
            w = min(rng.uniform(w_min, w_max), length - pos)
            d = min(rng.uniform(d_min, d_max), room)
            sb = setback + rng.uniform(0.0, 0.6)
            if rng.random() < coverage and d > 3.0:
                a0, a1 = sx + ax * pos + ix * sb, sy + ay * pos + iy * sb
                e = pos + w
                f = sb + d
                b0, b1 = sx + ax * e + ix * f, sy + ay * e + iy * f
                lo_x, hi_x = min(a0, b0), max(a0, b0)
                lo_y, hi_y = min(a1, b1), max(a1, b1)
                free = True
                for k in range(n):
                    if (min(hi_x, boxes[k, 1]) - max(lo_x, boxes[k, 0]) > 0.3
                            and min(hi_y, boxes[k, 3]) - max(lo_y, boxes[k, 2]) > 0.3):
                        free = False
                        break
                if free:
                    if n == boxes.shape[0]:
                        grown = np.empty((2 * n, 4))
                        grown[:n] = boxes
                        boxes = grown
                    boxes[n, 0], boxes[n, 1], boxes[n, 2], boxes[n, 3] = lo_x, hi_x, lo_y, hi_y
                    n += 1
            pos += w
            if rng.random() < gap_prob:
                pos += rng.uniform(gap_min, gap_max)
    return boxes[:n].copy()
