"""Reward of :class:`~dstenv.envs.DSTGridEnv`: named terms, summed.

Every term is reported separately in ``info["rewards"]`` (already weighted), so a
user can re-weight them offline or train on a subset. The weights live in the
``reward`` config section (:func:`default_reward_config`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from dstenv.config import Section, between
from dstenv.sim.lanes import Control

__all__ = ["default_reward_config", "StepOutcome", "reward_terms", "GiveWayWatch", "GIVE_WAY",
           "SECTION"]

#: Junction controls at which the ego has to give way (``reward.give_way``).
GIVE_WAY = (Control.YIELD, Control.STOP)


def default_reward_config() -> dict[str, Any]:
    """The ``reward`` config section (units in comments)."""
    return {
        "progress": 0.1,  # [1/m] per metre advanced along the route
        "speed": 0.05,  # [-] per step, times min(speed / target_speed, 1)
        "target_speed": 9.0,  # [m/s] speed that earns the full speed term
        "collision": -10.0,  # [-] once, on a collision (the episode ends)
        "off_road": -5.0,  # [-] once, on leaving the road (the episode ends)
        "hard_brake": -0.5,  # [-] per step with deceleration above the threshold
        "hard_brake_threshold": 2.5,  # [m/s^2] deceleration above comfort counts as hard
        "arrived": 1.0,  # [-] once, on reaching the end of the route (scenes that have one)
        # [-] per step, times (speed - junction_speed_limit) / target_speed where positive,
        # while the next junction on the route is within junction_range and no green
        # signal lets the ego through (0: off, the default)
        "junction_speed": 0.0,
        "junction_speed_limit": 4.5,  # [m/s]
        "junction_range": 20.0,  # [m] route distance to the junction's entry (0 inside it)
        # [-] once, on entering a yield or stop junction without having slowed to
        # give_way_speed within give_way_range of its entry: the traffic rule the ego
        # breaks when it does not give way (0: off, the default)
        "give_way": 0.0,
        "give_way_speed": 1.5,  # [m/s]
        "give_way_range": 5.0,  # [m] before the entry
    }


@dataclass(frozen=True)
class StepOutcome:
    """What the reward looks at after one step.

    Attributes:
        progress: distance advanced along the route this step [m] (negative when
            reversing).
        speed: ego speed after the step [m/s].
        decel: deceleration over the step, ``(v_prev - v) / dt`` [m/s^2].
        collision, off_road, arrived: ego flags after the step.
        junction_dist: route distance to the next junction's entry after the step [m]
            (0 inside one, ``inf`` when the route holds none or it is not known).
        junction_green: whether a green signal lets the ego through that junction.
        entered_give_way: the step took the ego into a junction whose control is yield
            or stop (it was before the entry, now it is inside).
        slowest_approach: the ego's lowest speed over the steps that began within
            ``give_way_range`` of that junction's entry [m/s] (``inf``: none).
    """

    progress: float
    speed: float
    decel: float
    collision: bool
    off_road: bool
    arrived: bool = False
    junction_dist: float = float("inf")
    junction_green: bool = False
    entered_give_way: bool = False
    slowest_approach: float = float("inf")


def reward_terms(out: StepOutcome, cfg: dict[str, Any]) -> dict[str, float]:
    """Weighted reward terms of one step; the reward is their sum.

    Args:
        out: the step's outcome.
        cfg: the ``reward`` section.

    Returns:
        ``{"progress", "speed", "collision", "off_road", "hard_brake", "arrived",
        "junction_speed", "give_way"}`` -> float.
    """
    target = cfg["target_speed"]
    speed_frac = min(max(out.speed, 0.0) / target, 1.0) if target > 0 else 0.0
    over = 0.0
    if out.junction_dist <= cfg["junction_range"] and not out.junction_green:
        over = max(out.speed - cfg["junction_speed_limit"], 0.0) / target
    return {
        "progress": cfg["progress"] * out.progress,
        "speed": cfg["speed"] * speed_frac,
        "collision": cfg["collision"] * float(out.collision),
        "off_road": cfg["off_road"] * float(out.off_road),
        "hard_brake": cfg["hard_brake"] * float(out.decel > cfg["hard_brake_threshold"]),
        "arrived": cfg["arrived"] * float(out.arrived),
        "junction_speed": cfg["junction_speed"] * over,
        "give_way": cfg["give_way"] * float(out.entered_give_way
                                            and out.slowest_approach > cfg["give_way_speed"]),
    }


class GiveWayWatch:
    """The ego's approach to a yield or stop junction, for the ``give_way`` term: the
    lowest speed over the steps that began within ``give_way_range`` of its entry, and
    whether a step took the ego inside. Call :meth:`before` and :meth:`after` around
    every world step (:meth:`reset` with the episode)."""

    def __init__(self) -> None:
        self.slowest = float("inf")  # [m/s]
        self._armed = False

    def reset(self) -> None:
        """Forget the approach (a new episode)."""
        self.slowest, self._armed = float("inf"), False

    def before(self, dist: float, gives_way: bool, speed: float, cfg: dict[str, Any]) -> None:
        """Before a step: ``dist`` [m] to the next junction's entry (0 inside), whether
        its control makes the ego give way, the ego's ``speed`` [m/s], the ``reward``
        section."""
        self._armed = dist > 0.0 and gives_way
        if not self._armed:
            self.slowest = float("inf")
        elif dist <= cfg["give_way_range"]:
            self.slowest = min(self.slowest, speed)

    def after(self, dist: float) -> tuple[bool, float]:
        """After the step, ``dist`` [m] to the next junction's entry: ``(entered,
        slowest)`` for :class:`StepOutcome`'s ``entered_give_way`` and
        ``slowest_approach``."""
        entered, slowest = self._armed and dist == 0.0, self.slowest
        if entered:
            self.slowest = float("inf")
        return entered, slowest


_W = between(-1e3, 1e3)  # a reward weight: finite and not absurd

#: The ``reward`` section of the env configuration.
SECTION = Section(default_reward_config, {
    "progress": _W, "speed": _W, "collision": _W, "off_road": _W, "hard_brake": _W,
    "arrived": _W, "junction_speed": _W, "give_way": _W,
    "junction_speed_limit": between(0.0, 60.0, "m/s"),
    "give_way_speed": between(0.0, 60.0, "m/s"),
    "give_way_range": between(0.0, 1e3, "m"),
    "junction_range": between(0.0, 1e3, "m"),
    "target_speed": between(0.0, 60.0, "m/s", lo_open=True),
    "hard_brake_threshold": between(0.0, 20.0, "m/s^2"),
})
