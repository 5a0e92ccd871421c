"""Action modes of :class:`~dstenv.envs.DSTGridEnv`: a dict registry.

A mode declares its space and the meaning of each discrete action, and builds a
*controller* per episode that turns the agent's action into what the world
source's ``step`` takes:

* ``"discrete"``: ``Discrete(5)`` meta-actions :data:`META_ACTIONS`, whatever the
  world. On a highway-env scene they are highway-env's own (its route-following
  ``MDPVehicle``; LEFT / RIGHT change lane; its speed controller brakes at most
  ``brake_decel``). On the city, SLOWER / IDLE / FASTER step a target speed through
  ``target_speeds`` (a P-controller with gain ``speed_gain`` tracks it, braking at
  most ``brake_decel``), LEFT / RIGHT choose the turn at the next junction
  (``World.set_turn``; like IDLE where the junction has no such turn), and the
  world's route-following steering (:meth:`dstenv.sim.World.route_steer`, the
  autopilot's rule) drives the planned route.
* ``"speed"``: ``Discrete(3)`` = SLOWER, IDLE, FASTER: the first three meta-actions
  alone, for tasks where the route fixes the turns (``DSTGrid-Occluded-v0``).
* ``"continuous"``: ``Box(-1, 1, (2,), float32)`` = (acceleration, steering) as
  fractions of ``max_accel`` [m/s^2] and ``max_steer`` [rad], positive steering to
  the left.
* ``"autopilot"``: ``Discrete(1)``: the world's own autopilot drives (route
  following, IDM, right of way; it reads ground truth: a privileged reference).

The space depends on ``type`` alone, never on another key: ``get_action_meanings()``
of the env names every action.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from gymnasium import spaces

from dstenv.config import ConfigError, Section, between
from dstenv.registry import Registry

__all__ = ["META_ACTIONS", "SPEED_ACTIONS", "ActionMode", "ACTIONS", "action_mode",
           "highway_settings", "default_action_config", "SECTION"]

#: ``"discrete"`` action index -> meta-action name (city and highway-env scenes).
META_ACTIONS: tuple[str, ...] = ("SLOWER", "IDLE", "FASTER", "LEFT", "RIGHT")
#: ``"speed"`` action index -> name: the longitudinal meta-actions alone.
SPEED_ACTIONS: tuple[str, ...] = META_ACTIONS[:3]
_HIGHWAY_NAMES = {"SLOWER": "SLOWER", "IDLE": "IDLE", "FASTER": "FASTER",
                  "LEFT": "LANE_LEFT", "RIGHT": "LANE_RIGHT"}


def default_action_config() -> dict[str, Any]:
    """The ``action`` config section (units in comments)."""
    return {
        # "discrete" (5 meta-actions) | "speed" (SLOWER, IDLE, FASTER) | "continuous"
        # (accel, steer) | "autopilot" (the world's own driver, privileged)
        "type": "discrete",
        "target_speeds": [0.0, 4.5, 9.0],  # [m/s] speeds SLOWER / FASTER step through
        "initial_speed_index": 2,  # index into target_speeds at reset
        "speed_gain": 1.0,  # [1/s] accel = gain * (target - speed), clipped
        "max_accel": 3.0,  # [m/s^2] continuous-action scale and discrete accel limit
        # [m/s^2] discrete braking limit: below the reward's hard_brake_threshold, so a
        # SLOWER meta-action brakes comfortably; continuous control can brake harder
        "brake_decel": 2.4,
        "max_steer": 0.5,  # [rad] continuous-action steering scale
        # [steps] world steps (0.1 s each) per env step: the policy acts at 10 / repeat
        # Hz; a meta-action is applied once, then held (IDLE), a continuous action or the
        # autopilot repeats; rewards are summed over the steps (highway-env's
        # policy_frequency)
        "repeat": 1,
    }


class Controller(Protocol):
    def world_action(self, action: Any) -> Any: ...

    def imitate(self, accel: float, steer: float) -> Any:
        """The action of this mode closest to the world command ``(accel [m/s^2],
        steer [rad])`` (a teacher's label: ``info.autopilot``)."""


#: [m/s^2] accelerations within this of 0 count as "hold the speed" in
#: :meth:`_CityMeta.imitate`
HOLD_BAND = 0.25


class _HighwayMeta:
    """Discrete meta-actions passed to highway-env by name."""

    def __init__(self, cfg: dict[str, Any], world: Any, names: tuple[str, ...]) -> None:
        self.names = names

    def world_action(self, action: Any) -> str:
        return _HIGHWAY_NAMES[self.names[int(action)]]

    def imitate(self, accel: float, steer: float) -> int:
        raise ConfigError("config.info.autopilot: highway-env's world has no autopilot "
                          "command to imitate; use source 'city'")


class _Continuous:
    """(accel, steer) fractions -> physical units."""

    def __init__(self, cfg: dict[str, Any], world: Any, names: tuple[str, ...]) -> None:
        self.scale = np.array([cfg["max_accel"], cfg["max_steer"]], np.float64)

    def world_action(self, action: Any) -> tuple[float, float]:
        raw = np.asarray(action)
        if raw.dtype.kind not in "biuf":  # complex: a warning and the real part; text: junk
            raise ValueError(f"continuous action: expected 2 real numbers (acceleration, "
                             f"steering in [-1, 1]), got {raw.dtype} {raw.tolist()!r}")
        a = raw.astype(np.float64)
        if a.size != 2 or not np.isfinite(a).all():
            raise ValueError(f"continuous action: expected 2 finite numbers (acceleration, "
                             f"steering in [-1, 1]), got {np.asarray(action).tolist()!r}")
        a = np.clip(a.reshape(2), -1.0, 1.0) * self.scale
        return float(a[0]), float(a[1])

    def imitate(self, accel: float, steer: float) -> np.ndarray:
        return np.clip(np.array([accel, steer]) / self.scale, -1.0, 1.0).astype(np.float32)


class _Autopilot:
    """The world's autopilot: every world source takes ``None`` as "drive yourself"."""

    def __init__(self, cfg: dict[str, Any], world: Any, names: tuple[str, ...]) -> None:
        pass

    def world_action(self, action: Any) -> None:
        return None

    def imitate(self, accel: float, steer: float) -> int:
        return 0


class _CityMeta:
    """Longitudinal meta-actions on the city: a target speed; the route steers.

    Steering is the world's route-following rule (:meth:`dstenv.sim.World.route_steer`,
    the autopilot's), so the agent decides how fast to go (and, with LEFT / RIGHT,
    which way at the next junction).
    """

    def __init__(self, cfg: dict[str, Any], world: Any, names: tuple[str, ...]) -> None:
        self.names = names
        self.speeds = [float(v) for v in cfg["target_speeds"]]
        self.index = int(np.clip(cfg["initial_speed_index"], 0, len(self.speeds) - 1))
        self.gain = float(cfg["speed_gain"])
        self.max_accel = float(cfg["max_accel"])
        self.brake = min(float(cfg["brake_decel"]), self.max_accel)
        self.world = world

    @property
    def target_speed(self) -> float:
        """The target speed the meta-actions have set [m/s]."""
        return self.speeds[self.index]

    def world_action(self, action: Any) -> tuple[float, float]:
        from dstenv.sim.lanes import Turn

        name = self.names[int(action)]
        if name in ("LEFT", "RIGHT"):
            self.world.set_turn(Turn[name])
        elif name == "SLOWER":
            self.index = max(self.index - 1, 0)
        elif name == "FASTER":
            self.index = min(self.index + 1, len(self.speeds) - 1)
        return self._accel(self.index), self.world.route_steer()

    def _accel(self, index: int) -> float:
        """[m/s^2] the P-controller's acceleration towards ``speeds[index]`` now."""
        return float(np.clip(self.gain * (self.speeds[index] - self.world.ego_speed),
                             -self.brake, self.max_accel))

    def imitate(self, accel: float, steer: float) -> int:
        """SLOWER, IDLE or FASTER, whichever target speed it sets drives most like
        ``accel``: among the actions that accelerate, hold or brake as ``accel`` does
        (within :data:`HOLD_BAND` of 0 counts as holding) the one whose acceleration now
        is closest, IDLE first on ties; the closest of all if none does (the route
        steers: ``steer`` is not needed)."""
        top = len(self.speeds) - 1
        index = {"IDLE": self.index, "SLOWER": max(self.index - 1, 0),
                 "FASTER": min(self.index + 1, top)}
        def sense(a: float) -> int:  # -1 brake, 0 hold, +1 accelerate
            return int(np.sign(a)) if abs(a) > HOLD_BAND else 0

        acc = {n: self._accel(i) for n, i in index.items()}
        same = [n for n in acc if sense(acc[n]) == sense(accel)]
        best = min(same or list(acc), key=lambda n: abs(acc[n] - accel))
        return self.names.index(best)


@dataclass(frozen=True)
class ActionMode:
    """One action mode: its space, the names of its discrete actions and its
    controllers per world source.

    Attributes:
        name: the ``action.type`` value.
        names: discrete action index -> meaning; empty for continuous modes.
        controllers: world source -> controller class ``(cfg, world, names)``.
    """

    name: str
    names: tuple[str, ...]
    controllers: dict[str, type]

    def space(self, cfg: dict[str, Any], source: str) -> spaces.Space:
        """The action space (the same for every ``source``)."""
        if self.names:
            if self.name != "autopilot" and len(cfg["target_speeds"]) < 1:
                raise ConfigError("config.action.target_speeds: needs at least one speed")
            return spaces.Discrete(len(self.names))
        return spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)

    def held(self, action: Any) -> Any:
        """The action for the world steps after the first of one env step
        (``action.repeat``): IDLE for meta-actions (a target speed, a turn or a lane
        change is chosen once), the action itself otherwise."""
        return self.names.index("IDLE") if "IDLE" in self.names else action

    def controller(self, cfg: dict[str, Any], world: Any, source: str) -> Controller:
        """A fresh controller for one episode on ``world`` (a ``source`` world)."""
        if source not in self.controllers:
            raise ConfigError(f"config.action.type: {self.name!r} has no controller for "
                              f"source {source!r}; known: {', '.join(self.controllers)}")
        return self.controllers[source](cfg, world, self.names)


#: mode name -> :class:`ActionMode`
ACTIONS: Registry[ActionMode] = Registry("mode", "action.type", {
    "discrete": ActionMode("discrete", META_ACTIONS, {"city": _CityMeta, "highway": _HighwayMeta}),
    "speed": ActionMode("speed", SPEED_ACTIONS, {"city": _CityMeta, "highway": _HighwayMeta}),
    "continuous": ActionMode("continuous", (), {"city": _Continuous, "highway": _Continuous}),
    "autopilot": ActionMode("autopilot", ("AUTOPILOT",), {"city": _Autopilot}),
})


def action_mode(name: str) -> ActionMode:
    """Look up a mode, with an error naming the known ones."""
    return ACTIONS.get(name)


def highway_settings(cfg: Mapping[str, Any]) -> dict[str, Any]:
    """The ``highway`` keys that follow the env's ``action`` section (one section drives
    either world: the meta-actions' speeds and braking limit reach highway-env's vehicle
    as they reach the city's controller), after refusing what a world cannot take.

    Raises:
        ConfigError: speeds that do not increase; elsewhere an ``initial_speed_index``
            past them; on ``source = "highway"``:
            ``info.autopilot``, ``action.type = "autopilot"``, ``initial_speed_index``
            or ``speed_gain`` (city only), fewer than two speeds, or ``action`` and
            ``highway`` speeds that differ.
    """
    from dstenv.sim.highway import default_config as highway_defaults

    act, speeds = cfg["action"], [float(v) for v in cfg["action"]["target_speeds"]]
    theirs = [float(v) for v in cfg["highway"]["target_speeds"]]
    for key, v in (("action", speeds), ("highway", theirs)):
        if any(b <= a for a, b in zip(v, v[1:])):
            raise ConfigError(f"config.{key}.target_speeds: must increase (SLOWER steps "
                              f"down, FASTER up), got {v}")
    out = {"action_mode": "continuous" if act["type"] == "continuous" else "meta",
           "brake_decel": min(act["brake_decel"], act["max_accel"])}
    if cfg["source"] != "highway":  # (highway-env's vehicle does not read the index)
        if act["initial_speed_index"] >= len(speeds):
            raise ConfigError(f"config.action.target_speeds: {speeds} has no index "
                              f"{act['initial_speed_index']} (the speed at reset, action."
                              "initial_speed_index): give more speeds or an index in "
                              f"0 .. {len(speeds) - 1}")
        return out
    if cfg["info"]["autopilot"]:
        raise ConfigError("config.info.autopilot: highway-env's world has no autopilot to "
                          "ask; use source 'city' or set info.autopilot = false")
    if act["type"] == "autopilot":  # its IDLE keeps lane and speed: no driver of its own
        raise ConfigError("config.action.type: 'autopilot' is the city world's driver; "
                          "highway-env's world has none (use source 'city', or action.type "
                          "'discrete' and IDLE to keep lane and speed)")
    mine = default_action_config()
    for key in ("initial_speed_index", "speed_gain"):
        if act[key] != mine[key]:
            raise ConfigError(f"config.action.{key}: the city world's controller only "
                              "(highway-env's vehicle tracks its speeds itself and does not "
                              "read it); leave it out")
    if speeds != mine["target_speeds"] and theirs not in (speeds, highway_defaults()[
            "target_speeds"]):
        raise ConfigError(f"config.action.target_speeds {speeds} and config.highway."
                          f"target_speeds {theirs} differ; set one of them")
    key = "action" if speeds != mine["target_speeds"] else "highway"
    out["target_speeds"] = speeds if key == "action" else theirs
    if len(out["target_speeds"]) < 2:
        raise ConfigError(f"config.{key}.target_speeds: highway-env's vehicle needs at least "
                          f"two speeds, got {out['target_speeds']}")
    return out


#: The ``action`` section of the env configuration.
SECTION = Section(default_action_config, {
    "target_speeds": between(0.0, 60.0, "m/s"),
    "initial_speed_index": between(0, 100),
    "speed_gain": between(0.0, 100.0, "1/s", lo_open=True),
    "max_accel": between(0.0, 20.0, "m/s^2", lo_open=True),
    "brake_decel": between(0.0, 20.0, "m/s^2", lo_open=True),
    "max_steer": between(0.0, 1.2, "rad", lo_open=True),
    "repeat": between(1, 100, "steps"),
}, (
    ("type", lambda c: action_mode(c["type"]) is not None, "unknown mode"),
    ("target_speeds", lambda c: len(c["target_speeds"]) >= 1, "needs at least one speed"),
))
