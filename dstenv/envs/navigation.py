"""What a driver knows besides the perception grid: its own state and its route.

The ``"dict"`` observation of :class:`~dstenv.envs.DSTGridEnv` is
``{"grid": ..., "ego": (E,) float32, "route": (2 K,) float32}``. One ego-centred
grid shows neither how fast the ego drives nor where its route goes at the next
junction; a car's instruments and navigation system do. Everything here is scaled
into ``[-1, 1]`` (stable-baselines3 feeds ``Box`` vectors to the policy as they are).

``ego`` (:data:`EGO_FEATURES`, in this order):

=================== =======================================================================
``speed``           ego speed / :data:`SPEED_SCALE`, in [0, 1]
``accel``           (v - v_prev) / dt over the last step / :data:`ACCEL_SCALE`, clipped
``steer``           steering angle of the last step / :data:`STEER_SCALE`, clipped
``target_speed``    the target speed the meta-actions set / :data:`SPEED_SCALE` (0 for
                    other action modes)
``junction_dist``   route distance to the next junction / :data:`JUNCTION_RANGE`, 1 when
                    none lies within that range
``control_none``    one-hot control of that junction (``dstenv.sim.lanes.Control``):
``control_yield``   none (a bend, or no junction ahead), yield (first come, first
``control_stop``    served), all-way stop, traffic signal
``control_signal``
``signal_green``    1 when that junction's signal shows green for the ego's lane
=================== =======================================================================

``route``: the route points ``spacing, 2 spacing, ..., K spacing`` metres ahead of the
ego, in its frame (x forward, y left) divided by ``K spacing``, flat ``x1, y1, x2, y2,
...`` (stable-baselines3 takes 1-D vectors: ``route.reshape(K, 2)`` gives the points).

Worlds that lack a feature (highway-env scenes have no junction controls or route
polyline) give its neutral value: no junction ahead, zero route points.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium import spaces

__all__ = ["EGO_FEATURES", "SPEED_SCALE", "ACCEL_SCALE", "STEER_SCALE", "JUNCTION_RANGE",
           "navigation_spaces", "ego_vector", "route_points"]

EGO_FEATURES: tuple[str, ...] = (
    "speed", "accel", "steer", "target_speed", "junction_dist",
    "control_none", "control_yield", "control_stop", "control_signal", "signal_green",
)
SPEED_SCALE = 15.0  # [m/s] the city ego's top speed
ACCEL_SCALE = 5.0  # [m/s^2]
STEER_SCALE = 0.6  # [rad] the city ego's steering limit
JUNCTION_RANGE = 60.0  # [m] junctions further ahead read as "none"


def navigation_spaces(route_points: int) -> dict[str, spaces.Box]:
    """``{"ego": Box(-1, 1, (E,)), "route": Box(-1, 1, (2 K,))}``, float32."""
    return {
        "ego": spaces.Box(-1.0, 1.0, (len(EGO_FEATURES),), dtype=np.float32),
        "route": spaces.Box(-1.0, 1.0, (2 * route_points,), dtype=np.float32),
    }


def ego_vector(world: Any, accel: float, target_speed: float) -> np.ndarray:
    """The ``ego`` features of :data:`EGO_FEATURES` for a world source.

    Args:
        world: a world source (``ego_speed``; optionally ``ego_steer`` and
            ``next_junction()`` as :class:`dstenv.sim.World` has them).
        accel: the ego's acceleration over the last step [m/s^2].
        target_speed: the meta-actions' target speed [m/s] (0 when none).

    Returns:
        ``(E,) float32`` in [-1, 1].
    """
    out = np.zeros(len(EGO_FEATURES), np.float32)
    out[0] = world.ego_speed / SPEED_SCALE
    out[1] = accel / ACCEL_SCALE
    out[2] = getattr(world, "ego_steer", 0.0) / STEER_SCALE
    out[3] = target_speed / SPEED_SCALE
    dist, control, green = (world.next_junction() if hasattr(world, "next_junction")
                            else (math.inf, 0, False))
    near = dist <= JUNCTION_RANGE
    out[4] = dist / JUNCTION_RANGE if near else 1.0
    out[5 + (int(control) if near else 0)] = 1.0
    out[9] = float(bool(green) and near)
    return np.clip(out, -1.0, 1.0, out=out)


def route_points(world: Any, pose: np.ndarray, k: int, spacing: float) -> np.ndarray:
    """The next ``k`` route points in the ego frame, scaled: ``(2 k,) float32``
    (``x1, y1, x2, y2, ...``).

    Args:
        world: a world source; one without ``route_polyline(ahead, spacing)`` gives zeros.
        pose: ``(3,)`` ego pose ``(x, y, yaw)``.
        k: number of points; spacing: [m] between them.
    """
    if k == 0 or not hasattr(world, "route_polyline"):
        return np.zeros(2 * k, np.float32)
    ahead = k * spacing
    pts = world.route_polyline(ahead=ahead, spacing=spacing)[1:k + 1]
    d = pts - pose[:2]
    c, s = math.cos(pose[2]), math.sin(pose[2])
    local = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]], axis=1)
    return np.clip(local / ahead, -1.0, 1.0).astype(np.float32).reshape(-1)
