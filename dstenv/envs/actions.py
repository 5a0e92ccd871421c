"""Action modes of :class:`~dstenv.envs.DSTGridEnv`: a dict registry.

A mode declares its space and builds a *controller* per episode that turns the
agent's action into what the world source's ``step`` takes:

* ``"discrete"``: meta-actions. On a highway-env scene, ``Discrete(5)``
  :data:`META_ACTIONS` = highway-env's own (its route-following ``MDPVehicle``;
  LEFT / RIGHT change lane). On the city, ``Discrete(5)`` with the same names:
  SLOWER / IDLE / FASTER step a target speed through ``target_speeds`` (a
  P-controller with gain ``speed_gain`` tracks it), LEFT / RIGHT choose the turn at
  the next junction (``World.set_turn``; ignored where the junction has no such
  turn), and the autopilot's route-following steering drives the planned route: the
  agent decides where to go and when to slow, e.g. before a blind junction.
  ``turns = false`` keeps only the first three (``Discrete(3)``: speed only).
* ``"continuous"``: ``Box(-1, 1, (2,), float32)`` = (acceleration, steering) as
  fractions of ``max_accel`` [m/s^2] and ``max_steer`` [rad], positive steering to
  the left.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from gymnasium import spaces

from dstenv.config import ConfigError, Section, between
from dstenv.registry import Registry

__all__ = ["META_ACTIONS", "CITY_META_ACTIONS", "ActionMode", "ACTIONS", "action_mode",
           "default_action_config", "SECTION"]

#: Discrete action index -> meta-action name (highway-env scenes: all five).
META_ACTIONS: tuple[str, ...] = ("SLOWER", "IDLE", "FASTER", "LEFT", "RIGHT")
#: The city's discrete actions: the same names; LEFT / RIGHT pick the next junction's turn.
CITY_META_ACTIONS: tuple[str, ...] = META_ACTIONS
_HIGHWAY_NAMES = {"SLOWER": "SLOWER", "IDLE": "IDLE", "FASTER": "FASTER",
                  "LEFT": "LANE_LEFT", "RIGHT": "LANE_RIGHT"}


def default_action_config() -> dict[str, Any]:
    """The ``action`` config section (units in comments)."""
    return {
        "type": "discrete",  # "discrete" (meta-actions) | "continuous" (accel, steer)
        "turns": True,  # city: LEFT / RIGHT choose the next junction's turn; false: speed only
        "target_speeds": [0.0, 4.5, 9.0],  # [m/s] speeds SLOWER / FASTER step through
        "initial_speed_index": 2,  # index into target_speeds at reset
        "speed_gain": 1.0,  # [1/s] accel = gain * (target - speed), clipped
        "max_accel": 3.0,  # [m/s^2] continuous-action scale and discrete accel limit
        # [m/s^2] discrete braking limit: below the reward's hard_brake_threshold, so a
        # SLOWER meta-action brakes comfortably; continuous control can brake harder
        "brake_decel": 2.4,
        "max_steer": 0.5,  # [rad] continuous-action steering scale
    }


class Controller(Protocol):
    def world_action(self, action: Any) -> Any: ...


class _HighwayMeta:
    """Discrete meta-actions passed to highway-env by name."""

    def __init__(self, cfg: dict[str, Any], world: Any) -> None:
        pass

    def world_action(self, action: Any) -> str:
        return _HIGHWAY_NAMES[META_ACTIONS[int(action)]]


class _Continuous:
    """(accel, steer) fractions -> physical units."""

    def __init__(self, cfg: dict[str, Any], world: Any) -> None:
        self.scale = np.array([cfg["max_accel"], cfg["max_steer"]], np.float64)

    def world_action(self, action: Any) -> tuple[float, float]:
        a = np.clip(np.asarray(action, np.float64).reshape(2), -1.0, 1.0) * self.scale
        return float(a[0]), float(a[1])


class _CityMeta:
    """Longitudinal meta-actions on the city: a target speed; the route steers.

    Steering is the autopilot's rule (pure pursuit of the route point
    ``clip(2.5 + 0.6 v, 4, 15)`` m ahead), so the agent decides only how fast to go.
    """

    def __init__(self, cfg: dict[str, Any], world: Any) -> None:
        self.speeds = [float(v) for v in cfg["target_speeds"]]
        self.index = int(np.clip(cfg["initial_speed_index"], 0, len(self.speeds) - 1))
        self.gain = float(cfg["speed_gain"])
        self.max_accel = float(cfg["max_accel"])
        self.brake = min(float(cfg["brake_decel"]), self.max_accel)
        self.world = world

    def world_action(self, action: Any) -> tuple[float, float]:
        from dstenv.sim.ego import pure_pursuit
        from dstenv.sim.lanes import Turn

        name = CITY_META_ACTIONS[int(action)]
        if name in ("LEFT", "RIGHT"):
            self.world.set_turn(Turn[name])
        elif name == "SLOWER":
            self.index = max(self.index - 1, 0)
        elif name == "FASTER":
            self.index = min(self.index + 1, len(self.speeds) - 1)
        w = self.world
        v = w.ego_speed
        accel = float(np.clip(self.gain * (self.speeds[self.index] - v), -self.brake,
                              self.max_accel))
        look = float(np.clip(2.5 + 0.6 * v, 4.0, 15.0))
        target = w.route_polyline(ahead=look, spacing=look)[-1]
        x, y, yaw = w.ego_pose
        ego = w.config["ego"]
        steer = pure_pursuit(x, y, yaw, (float(target[0]), float(target[1])),
                             ego["wheelbase"], ego["max_steer"])
        return accel, steer


@dataclass(frozen=True)
class ActionMode:
    """One action mode: its space and its controllers per world source."""

    name: str
    controllers: dict[str, type]

    def space(self, cfg: dict[str, Any], source: str) -> spaces.Space:
        """The action space for a ``source`` world."""
        if self.name == "discrete":
            if len(cfg["target_speeds"]) < 1:
                raise ConfigError("config.action.target_speeds: needs at least one speed")
            if source == "city":
                return spaces.Discrete(len(CITY_META_ACTIONS) if cfg["turns"] else 3)
            return spaces.Discrete(len(META_ACTIONS))
        return spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)

    def controller(self, cfg: dict[str, Any], world: Any, source: str) -> Controller:
        """A fresh controller for one episode on ``world`` (a ``source`` world)."""
        if source not in self.controllers:
            raise ConfigError(f"config.action.type: {self.name!r} has no controller for "
                              f"source {source!r}; known: {', '.join(self.controllers)}")
        return self.controllers[source](cfg, world)


#: mode name -> :class:`ActionMode`
ACTIONS: Registry[ActionMode] = Registry("mode", "action.type", {
    "discrete": ActionMode("discrete", {"city": _CityMeta, "highway": _HighwayMeta}),
    "continuous": ActionMode("continuous", {"city": _Continuous, "highway": _Continuous}),
})


def action_mode(name: str) -> ActionMode:
    """Look up a mode, with an error naming the known ones."""
    return ACTIONS.get(name)


#: The ``action`` section of the env configuration.
SECTION = Section(default_action_config, {
    "target_speeds": between(0.0, 60.0, "m/s"),
    "initial_speed_index": between(0, 100),
    "speed_gain": between(0.0, 100.0, "1/s", lo_open=True),
    "max_accel": between(0.0, 20.0, "m/s^2", lo_open=True),
    "brake_decel": between(0.0, 20.0, "m/s^2", lo_open=True),
    "max_steer": between(0.0, 1.2, "rad", lo_open=True),
}, (
    ("type", lambda c: action_mode(c["type"]) is not None, "unknown mode"),
    ("target_speeds", lambda c: len(c["target_speeds"]) >= 1, "needs at least one speed"),
    ("initial_speed_index", lambda c: c["initial_speed_index"] < len(c["target_speeds"]),
     "must index target_speeds"),
))
