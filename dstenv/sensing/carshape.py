"""What the 3-D LIDAR sees of a car: a body on wheels, not a prism from the ground.

``lidar.hdl64.vehicle_shape``: ``"box"`` casts every agent as the prism of its
footprint from ``z = 0`` to its height (the occluder contract of
:mod:`dstenv.sim.types`); ``"car"`` casts :attr:`~dstenv.sim.types.AgentKind.CAR`
agents as a few boxes, each an extruded rectangle the box caster
(:func:`dstenv.sensing.cast3d.cast_boxes`) already handles:

* the lower body, from the ground clearance to the belt line, as the union of two
  boxes (the full length one narrower by ``CORNER_Y`` a side, the full width one
  shorter by ``CORNER_X`` an end): the plan view's corners are cut, as a real car's
  rounded bumpers and wings are;
* the cabin (cars up to ``CABIN_MAX_HEIGHT``; vans and trucks keep the lower body up
  to their roof): the middle of the length, a little aft, narrower by
  ``TUMBLEHOME`` a side, from the belt line to the roof;
* the two axles: the wheels under the body, ``WHEEL_HALF_LENGTH`` either side of the
  axle, inside the body's width; between them a beam may pass under the sills and
  meet the road beneath the car.

The labelled footprint is the agent's full box either way (as a KITTI box around a
real car), so its rim cells are only partly covered by the car's surface: the real
scans' rim cells are seen free in earlier sweeps far more often than the prisms'
(``docs/realism.md``, "Parked cars' rims"). Cyclists and pedestrians stay prisms.

Every part's row keeps the agent's index (``Cloud.index`` names the agent); the
agent's first row is its lower body's long box, so ``boxes[i]`` is still agent ``i``'s
(the incidence of :mod:`dstenv.sensing.fading`), and the other parts follow the
clutter rows.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["VEHICLE_SHAPES", "CLEARANCE", "BELT", "CORNER_X", "CORNER_Y", "TUMBLEHOME",
           "CABIN_MAX_HEIGHT", "car_part_rows"]

#: ``lidar.hdl64.vehicle_shape`` values.
VEHICLE_SHAPES: tuple[str, ...] = ("box", "car")
#: [m] underside of the body above the road (a passenger car: 0.14-0.2 m)
CLEARANCE: float = 0.18
#: belt line (top of bonnet, wings and boot) as a share of the roof height
BELT: float = 0.62
#: [m] plan-view corner cut, along the length and across it (rounded bumpers)
CORNER_X: float = 0.35
CORNER_Y: float = 0.2
#: [m] the cabin's narrowing a side (glass and pillars lean in)
TUMBLEHOME: float = 0.12
#: [m] agents taller than this (vans, trucks) have no separate cabin
CABIN_MAX_HEIGHT: float = 1.8
#: cabin half-length as a share of the length, and its centre behind the middle
CABIN_HALF: float = 0.25
CABIN_AFT: float = 0.06
#: [m] axle from the body's end, wheel radius along the length, wheel inset a side
AXLE_FROM_END: float = 0.85
WHEEL_HALF_LENGTH: float = 0.32
WHEEL_INSET: float = 0.08


@numba.njit(cache=True)
def car_part_rows(xy, yaw, length, width, height, is_car, surface, out):  # pragma: no cover
    """Rewrite the car agents' rows of a box table and return their extra part rows.

    Args:
        xy: ``(N, 2) float64`` agent centres [m]; yaw ``(N,)`` [rad]; length, width,
            height ``(N,) float64`` [m]; is_car ``(N,) bool`` (the agents to shape).
        surface: the surface code of the rows (the LIDAR's agent material).
        out: ``(N + K, 11)`` box table whose first N rows are the agents' prisms
            (``cx, cy, cos, sin, half_l, half_w, z_lo, z_hi, surface, index, r``);
            row ``i`` of a car becomes its lower body's long box, in place.

    Returns:
        ``(M, 11) float64`` the other parts' rows (cross box, cabin, two axles),
        index ``i`` each.
    """
    n = xy.shape[0]
    cars = 0
    for i in range(n):
        if is_car[i]:
            cars += 1
    extra = np.empty((4 * cars, 11))
    m = 0
    for i in range(n):
        if not is_car[i]:
            continue
        hl = length[i] / 2
        hw = width[i] / 2
        h = height[i]
        ca = math.cos(yaw[i])
        sa = math.sin(yaw[i])
        cut_x = min(CORNER_X, 0.2 * hl)
        cut_y = min(CORNER_Y, 0.25 * hw)
        cabin = h <= CABIN_MAX_HEIGHT
        top = BELT * h if cabin else h
        r = math.hypot(hl, hw)
        # lower body, long box (the agent's own row)
        out[i, 5] = hw - cut_y
        out[i, 6] = CLEARANCE
        out[i, 7] = top
        # lower body, wide box
        _row(extra, m, xy[i, 0], xy[i, 1], ca, sa, hl - cut_x, hw, CLEARANCE, top, surface, i, r)
        m += 1
        # cabin, or a second copy of the wide box's span for a van (an empty part is
        # not allowed: the table's size is fixed), zero height at the roof
        if cabin:
            off = -CABIN_AFT * length[i]
            _row(extra, m, xy[i, 0] + off * ca, xy[i, 1] + off * sa, ca, sa, CABIN_HALF * length[i],
                 hw - TUMBLEHOME, top, h, surface, i, r)
        else:
            _row(extra, m, xy[i, 0], xy[i, 1], ca, sa, hl - cut_x, hw, top, top, surface, i, r)
        m += 1
        # axles: the wheels below the body
        ax = max(hl - AXLE_FROM_END, WHEEL_HALF_LENGTH)
        for s in (-1.0, 1.0):
            _row(extra, m, xy[i, 0] + s * ax * ca, xy[i, 1] + s * ax * sa, ca, sa,
                 WHEEL_HALF_LENGTH, hw - WHEEL_INSET, 0.0, CLEARANCE, surface, i, r)
            m += 1
    return extra


@numba.njit(cache=True)
def _row(t, m, cx, cy, ca, sa, hl, hw, zlo, zhi, surface, i, r):  # pragma: no cover - numba
    t[m, 0] = cx
    t[m, 1] = cy
    t[m, 2] = ca
    t[m, 3] = sa
    t[m, 4] = hl
    t[m, 5] = hw
    t[m, 6] = zlo
    t[m, 7] = zhi
    t[m, 8] = surface
    t[m, 9] = i
    t[m, 10] = r
