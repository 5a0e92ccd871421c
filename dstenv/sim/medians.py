"""Raised medians of the procedural city's wide streets.

A street line with at least two lanes per direction gets, with probability
``world.map.median_prob``, a raised strip ``median_width`` wide between its two
directions: the lanes move apart by half the width each (the street widens by the
median), the strip is :attr:`MapClass.INTERMEDIATE` ground (kerb-raised,
``non_navigable``, drawn as verge) and it stops at the stop lines, so left turns and
U-turns at junctions stay open. Its furniture comes from
:func:`dstenv.sim.clutter.median_clutter`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["draw_medians", "median_box"]


def draw_medians(lanes: np.ndarray, cfg: dict[str, Any], rng: np.random.Generator | None
             ) -> np.ndarray:
    """``(n,) float64`` median width of each street line [m] (0: none); only streets
    with >= 2 lanes per direction get one."""
    if rng is None or cfg["median_prob"] <= 0:
        return np.zeros(len(lanes))
    return np.where((lanes >= 2) & (rng.random(len(lanes)) < cfg["median_prob"]),
                    cfg["median_width"], 0.0)


def median_box(poly: np.ndarray, width: float, t_u: float, t_v: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """Corners (low, high) [m] of the raised median of an axis-aligned street
    ``poly (2, 2)``, broken ``t_u`` / ``t_v`` metres before its junctions (the stop lines)."""
    a, b = np.asarray(poly[0], float), np.asarray(poly[-1], float)
    d = (b - a) / np.hypot(*(b - a))
    p = np.abs(np.array([-d[1], d[0]]))
    lo, hi = a + d * t_u - p * width / 2, b - d * t_v + p * width / 2
    return np.minimum(lo, hi), np.maximum(lo, hi)
