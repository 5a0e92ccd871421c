"""The ``info`` dict of a ``DSTGridEnv`` step: the frame's arrays, the ego's state and
the episode's outcome (``is_success``, ``termination_reason``), plus opt-in extras."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from dstenv.config import ConfigError, Section, between
from dstenv.frame import Frame

__all__ = ["INFO_SECTION", "step_info"]

#: The ``info`` section: optional extras of the step's ``info`` dict.
INFO_SECTION = Section(lambda: {
    # add info["labels"] (H, W) uint8 and info["visible"] (H, W) bool: ground truth
    # computed every step (label_grid), ~15 % of a 256 x 256 step
    "labels": False,
    "lidar_points": False,  # add info["lidar_points"] (B, 2) float32 [m]
    # add info["autopilot_command"] (accel [m/s^2], steer [rad]) and
    # info["autopilot_action"]: what the world's autopilot would do now (privileged:
    # it reads ground truth; a teacher for imitation), city world only
    "autopilot": False,
    # [m] route progress that makes an episode without collision, off-road or arrival a
    # success (info["is_success"])
    "success_distance": 100.0,
}, {"success_distance": between(0.0, 1e5, "m")})


def step_info(frame: Frame, world: Any, terms: dict[str, float], progress: float,
              terminated: bool, cfg: Mapping[str, Any], controller: Any = None
              ) -> dict[str, Any]:
    """The step's ``info`` (keys documented on :class:`dstenv.envs.dstgrid.DSTGridEnv`).

    Args:
        frame: the step's frame; its arrays go in as they are (views, not copies).
        world: the world source (``ego_speed``, ``collision``, ``off_road`` and,
            where it has a destination, ``route_done``).
        terms: the step's weighted reward terms.
        progress: [m] along the route since reset.
        terminated: whether the step ends the episode (else the reason is "timeout").
        cfg: the validated ``info`` section.
        controller: the episode's action controller (``imitate``: the action closest to
            the autopilot's command), for ``info.autopilot``.
    """
    info: dict[str, Any] = {
        "sensor": frame.sensor,
        "gis": frame.gis,
        "ego_pose": frame.ego_pose,
        "ego_speed": float(world.ego_speed),
        "time": float(frame.time),
        "seed": frame.seed,
        "collision": bool(world.collision),
        "off_road": bool(world.off_road),
        "arrived": bool(getattr(world, "route_done", False)),
        "rewards": terms,
        "route_progress": progress,
    }
    if cfg["labels"]:
        info["labels"], info["visible"] = frame.labels, frame.visible
    crash, off, arrived = info["collision"], info["off_road"], info["arrived"]
    info["is_success"] = not (crash or off) and (arrived or progress >= cfg["success_distance"])
    info["termination_reason"] = (("collision" if crash else "off_road" if off else "arrived")
                                  if terminated else "timeout")
    if cfg["lidar_points"]:
        info["lidar_points"] = frame.extras["lidar_points"]
    if cfg["autopilot"]:
        info["autopilot_command"] = command = _shadow(world).command
        info["autopilot_action"] = controller.imitate(*command)
    return info


def _shadow(world: Any) -> Any:
    """The world's :class:`~dstenv.sim.shadow.ShadowAutopilot`, attached at first use."""
    from dstenv.sim.shadow import ShadowAutopilot

    if not hasattr(world, "shadow"):
        raise ConfigError(f"config.info.autopilot: the {type(world).__name__} world has no "
                          "autopilot to ask; use source 'city' or set info.autopilot = false")
    if world.shadow is None:
        world.shadow = ShadowAutopilot()
        world.shadow.update(world)
    return world.shadow
