"""Weak returns of the 3-D LIDAR: detection that fades with range and incidence.

Why. A real time-of-flight return is detected when its echo clears the receiver's
threshold. The echo of a Lambertian surface of reflectivity ``rho`` at slant range
``r``, met at the incidence angle ``theta`` (between the beam and the surface normal),
is proportional to ``rho cos(theta) / r^2``; paint, glass and speckle make it vary
from return to return. Far vehicles seen at grazing incidence therefore lose returns
from sweep to sweep: their silhouette in the sensor grid flickers, and a cell that a
ray crossed as free is occupied in the next sweep (DST moving evidence at a parked
car's rim, issue 14). The simulator's boxes otherwise return on every beam but the
flat ``dropout`` share.

Model (per return on an ``agent`` surface; other surfaces keep every return)::

    strength s = rho cos(theta) (fade_range / r)^2
    P(detected) = Phi(ln(s) / fade_sigma)

``rho`` is the surface's mean reflectance (:data:`dstenv.sensing.scene3d.REFLECTANCE`,
0.40 for agents), ``fade_range`` [m] the range at which a unit-reflectivity surface
met head-on is detected half the time (HDL-64E data sheet: cars, ~0.8, to 120 m and
pavement, ~0.1, to 50 m at normal incidence give 134-158 m), ``fade_sigma`` the
standard deviation of the natural log of a return's strength (log-normal fading) and
``Phi`` the standard normal CDF. ``fade_range = 0`` turns the model off.

``theta`` comes from the box face the beam met: a side face (horizontal normal along
one box axis) or the roof / a crown's underside (vertical normal). Each return draws
one uniform of its own counter stream (:func:`dstenv.sensing.draws.beam_uniform`),
so one seed gives one sweep.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from dstenv.sensing.draws import beam_uniform

__all__ = ["detection_probability", "incidence_cosine", "fade_returns"]


@numba.njit(cache=True, inline="always")
def detection_probability(rho, cos_inc, r, fade_range, sigma):  # pragma: no cover - numba
    """P(detected) of a return: ``Phi(ln(rho cos_inc (fade_range / r)^2) / sigma)``;
    1 when ``fade_range <= 0`` (off), 0 at ``cos_inc <= 0`` or ``rho <= 0``."""
    if fade_range <= 0.0:
        return 1.0
    s = rho * cos_inc * (fade_range / r) ** 2
    if not s > 0.0:
        return 0.0
    return 0.5 * math.erfc(-math.log(s) / (sigma * math.sqrt(2.0)))


@numba.njit(cache=True)
def incidence_cosine(box, ox, oy, ux, uy, slope, t):  # pragma: no cover - numba
    """``cos(theta)`` of a beam (origin ``(ox, oy)``, horizontal direction ``(ux, uy)``,
    ``slope = tan(elevation)``) meeting the box row ``box`` (:mod:`dstenv.sensing.
    cast3d` layout: ``cx, cy, cos, sin, half_l, half_w, ...``) at horizontal distance
    ``t``: on a side face ``cos(el) |u . n|``, on the roof or underside ``|sin(el)|``."""
    ca, sa = box[2], box[3]
    hx = ca * (ox + t * ux - box[0]) + sa * (oy + t * uy - box[1])
    hy = -sa * (ox + t * ux - box[0]) + ca * (oy + t * uy - box[1])
    gap_l = box[4] - abs(hx)  # how far inside the side planes the hit lies [m]
    gap_w = box[5] - abs(hy)
    cos_el = 1.0 / math.sqrt(1.0 + slope * slope)
    tol = 1e-6 * max(1.0, t)
    if min(gap_l, gap_w) > tol:  # strictly inside the footprint: roof or underside
        return abs(slope) * cos_el
    if gap_l <= gap_w:  # the face across the box's length: normal along its axis
        return cos_el * abs(ca * ux + sa * uy)
    return cos_el * abs(-sa * ux + ca * uy)


@numba.njit(cache=True)
def fade_returns(keep, key, best, surf, idx, boxes, surface, rho, ox, oy, ux, uy, slope,
                 sec_el, fade_range, sigma):  # pragma: no cover - numba
    """Clear ``keep[k]`` of the returns ``k`` (finite ``best``, column-major, as
    :mod:`dstenv.sensing.lidar3d` numbers them) on ``surface`` that fade: a uniform of
    stream ``key`` at or above their :func:`detection_probability`. ``boxes``: the
    sweep's box rows, agent ``i`` in row ``i``. Returns how many were cleared."""
    k = -1
    lost = 0
    for j in range(best.shape[0]):
        for c in range(best.shape[1]):
            if not best[j, c] < np.inf:
                continue
            k += 1
            if surf[j, c] != surface or not keep[k]:
                continue
            t = best[j, c]
            cos_inc = incidence_cosine(boxes[idx[j, c]], ox[j], oy[j], ux[j], uy[j],
                                       slope[c], t)
            p = detection_probability(rho, cos_inc, t * sec_el[c], fade_range, sigma)
            if beam_uniform(key, k) >= p:
                keep[k] = False
                lost += 1
    return lost
