"""A highway-env scene as a world source for the dstenv pipeline.

:class:`HighwayWorld` has the interface of :class:`dstenv.sim.World` (``reset``,
``step``, ``map``, ``agents``, ``ego_pose``, ``ego_speed``, ``time``, ``collision``,
``off_road``, ``route_progress``) but takes its road network and traffic from a
`highway-env <https://github.com/Farama-Foundation/HighwayEnv>`_ environment:

* every lane of the scene's road network is rasterised as road, the rest of the map
  (a ``margin`` around the lanes) as intermediate space;
* rectangular buildings are placed off-road (at least ``setback`` from any lane,
  seeded per episode) so that the LIDAR is occluded as in a city;
* highway-env's vehicles and obstacles become :class:`~dstenv.sim.types.Agents`;
  the ego is highway-env's controlled vehicle and receives the actions.

highway-env's coordinates are meant for a y-down screen (its traffic drives on the
right there). The adapter mirrors them (``y -> -y``, ``yaw -> -yaw``) into the
y-up world frame of :mod:`dstenv.grid`, so traffic drives on the right here too and
a positive steering angle turns left.

One step is 0.1 s: the scene runs with ``simulation_frequency`` and
``policy_frequency`` of 10 Hz. highway-env is imported lazily (only when a
:class:`HighwayWorld` is built).
"""

from __future__ import annotations

import copy
import functools
import importlib
from typing import Any

import numpy as np

from dstenv.config import PROB, ConfigError, Rule, Section, between, one_of, section
from dstenv.sim.highway_map import lane_points, mirror, place_buildings, rasterise_lanes
from dstenv.sim.types import AgentKind, Agents, WorldMap

__all__ = ["SCENES", "META_ACTIONS", "ENV_CONFIG_RULES", "SECTION", "default_config",
           "HighwayWorld"]

#: highway-env scene id -> ``"module:Class"`` of its environment. Extend it to add a
#: scene; the class must be a highway-env ``AbstractEnv``.
SCENES: dict[str, str] = {
    "intersection-v0": "highway_env.envs.intersection_env:IntersectionEnv",
    "intersection-v1": "highway_env.envs.intersection_env:ContinuousIntersectionEnv",
    "intersection-v2": "highway_env.envs.intersection_env:ConnectedLaneIntersectionEnv",
    "roundabout-v0": "highway_env.envs.roundabout_env:RoundaboutEnv",
    "highway-v0": "highway_env.envs.highway_env:HighwayEnv",
    "highway-fast-v0": "highway_env.envs.highway_env:HighwayEnvFast",
    "merge-v0": "highway_env.envs.merge_env:MergeEnv",
    "two-way-v0": "highway_env.envs.two_way_env:TwoWayEnv",
}

#: Meta-actions understood in ``"meta"`` action mode (highway-env's names).
META_ACTIONS: tuple[str, ...] = ("SLOWER", "IDLE", "FASTER", "LANE_LEFT", "LANE_RIGHT")

DT = 0.1  # [s] one step, the LIDAR period


def default_config() -> dict[str, Any]:
    """Defaults of the ``highway`` config section (units in comments)."""
    return {
        "scene": "intersection-v1",  # key of SCENES
        "action_mode": "meta",  # "meta": META_ACTIONS; "continuous": (accel, steer)
        "target_speeds": [0.0, 4.5, 9.0],  # [m/s] speeds of the meta-actions
        "brake_decel": 0.0,  # [m/s^2] meta mode: braking limit of the ego's speed controller
        #                      (DSTGridEnv passes action.brake_decel); 0 = highway-env's own
        "resolution": 0.25,  # [m] map raster cell
        "margin": 40.0,  # [m] intermediate border around the lanes' bounding box
        "max_extent": 1000.0,  # [m] half-size cap of the map around the ego start
        "buildings": {
            "per_hectare": 9.0,  # [1/ha] buildings per hectare of map
            "size_min": 6.0,  # [m] footprint edge
            "size_max": 22.0,  # [m]
            "setback": 3.0,  # [m] minimum distance to any lane (sidewalk)
            "gap": 2.0,  # [m] minimum distance between buildings
        },
        "env_config": {},  # extra highway-env config keys (ENV_CONFIG_RULES), checked
    }


#: The highway-env configuration keys a scenario may set, each with its allowed
#: values. An allow-list, never passed through blindly: a class path such as
#: ``other_vehicles_type`` would make highway-env import any module named in a data
#: file. Observation, action and simulation frequency are set by dstenv itself.
ENV_CONFIG_RULES: dict[str, Rule] = {
    "duration": between(1, 3600, "s"),
    "initial_vehicle_count": between(0, 200),
    "vehicles_count": between(0, 200),
    "vehicles_density": between(0.0, 10.0),
    "spawn_probability": PROB,
    "lanes_count": between(1, 8),
    "ego_spacing": between(0.0, 10.0),
    "destination": Rule(choices=("o0", "o1", "o2", "o3", None)),
    "reward_speed_range": between(0.0, 60.0, "m/s"),
    "collision_reward": between(-1e3, 1e3),
    "high_speed_reward": between(-1e3, 1e3),
    "arrived_reward": between(-1e3, 1e3),
    "right_lane_reward": between(-1e3, 1e3),
    "lane_change_reward": between(-1e3, 1e3),
    "normalize_reward": one_of(True, False),
    "offroad_terminal": one_of(True, False),
    "screen_width": between(100, 4000, "px"),
    "screen_height": between(100, 4000, "px"),
    "scaling": between(0.1, 100.0),
    "show_trajectories": one_of(True, False),
    "real_time_rendering": one_of(True, False),
}


def _env_config_ok(cfg: dict[str, Any]) -> bool:
    for key, value in cfg["env_config"].items():
        rule = ENV_CONFIG_RULES.get(key)
        if rule is None:
            raise ConfigError(f"highway.env_config.{key}: not an allowed highway-env key; "
                              f"allowed: {', '.join(sorted(ENV_CONFIG_RULES))}")
        if isinstance(value, (dict, str)) and rule.choices is None:
            raise ConfigError(f"highway.env_config.{key}: must be {rule.describe()}, "
                              f"got {value!r}")
        rule.check(value, f"highway.env_config.{key}")
    return True


#: The ``highway`` section.
SECTION = Section(default_config, {
    "scene": one_of(*SCENES, what="scene"),
    "action_mode": one_of("meta", "continuous"),
    "target_speeds": between(0.0, 60.0, "m/s"),
    "brake_decel": between(0.0, 20.0, "m/s^2"),
    "resolution": between(0.05, 2.0, "m"),
    "margin": between(0.0, 500.0, "m"),
    "max_extent": between(10.0, 5000.0, "m"),
    "buildings": {
        "per_hectare": between(0.0, 100.0, "1/ha"),
        "size_min": between(1.0, 200.0, "m"),
        "size_max": between(1.0, 200.0, "m"),
        "setback": between(0.0, 100.0, "m"),
        "gap": between(0.0, 100.0, "m"),
    },
}, (("env_config", _env_config_ok, "invalid highway-env key"),
    ("buildings.size_max", lambda c: c["buildings"]["size_min"] <= c["buildings"]["size_max"],
     "must be >= buildings.size_min")))
def _limited_speed_control(control: Any, vehicle: Any, limit: float, target_speed: float
                           ) -> float:
    """highway-env's speed controller with its braking capped at ``limit`` [m/s^2]."""
    return max(float(control(vehicle, target_speed)), -limit)


class _NullObservation:
    """Replaces highway-env's observation (the pipeline builds its own grids) with a
    constant element of the env's observation space, computed once."""

    def __init__(self, space: Any) -> None:
        if hasattr(space, "low") and hasattr(space, "high"):
            zero = np.clip(np.zeros(space.shape), space.low, space.high)
            self.value = zero.astype(space.dtype)
        else:
            self.value = space.sample()

    def observe(self) -> Any:
        return self.value


def _load_class(path: str) -> type:
    module, name = path.split(":")
    return getattr(importlib.import_module(module), name)


class HighwayWorld:
    """A highway-env scene seen through the dstenv world interface.

    Args:
        config: the ``highway`` section (merged over :func:`default_config`).
        seed: seed of the first episode (``reset`` takes a new one).
        env: an existing highway-env environment to use instead of building one
            from ``config["scene"]``; its configuration is left as it is.
        external: the caller steps and resets ``env`` itself (the
            :class:`dstenv.envs.DSTGridObservation` wrapper): :meth:`reset` only
            rebuilds the map around the current scene and :meth:`step` only
            advances the clock.

    Attributes:
        map: the scene's :class:`WorldMap` (rebuilt at every reset).
        agents: every vehicle and obstacle but the ego.
        ego_pose: ``(3,) float64`` ``(x [m], y [m], yaw [rad])``.
        ego_speed: [m/s]. time: [s] since reset. collision, off_road: ego flags.
        route_progress: distance [m] the ego advanced along its lanes since reset.
    """

    def __init__(self, config: dict[str, Any] | None = None, seed: int = 0,
                 env: Any = None, external: bool = False) -> None:
        self.config = section("highway", config)
        if env is None:
            env = _load_class(SCENES[self.config["scene"]])(config=self._env_config())
        self.env = env
        self.external = external
        self.dt = 1.0 / float(env.unwrapped.config["policy_frequency"])
        self.route_progress = 0.0
        self.time = 0.0
        if not external:
            self.reset(seed)

    def _env_config(self) -> dict[str, Any]:
        action: dict[str, Any]
        if self.config["action_mode"] == "meta":
            action = {"type": "DiscreteMetaAction", "longitudinal": True, "lateral": True,
                      "target_speeds": list(self.config["target_speeds"])}
        else:
            action = {"type": "ContinuousAction", "longitudinal": True, "lateral": True}
        cfg = {"simulation_frequency": round(1 / DT), "policy_frequency": round(1 / DT),
               "action": action, "offroad_terminal": False}
        cfg.update(copy.deepcopy(self.config["env_config"]))
        return cfg

    # -- episode ---------------------------------------------------------------------
    def reset(self, seed: int) -> None:
        """Start a new episode: new scene traffic and new buildings, from ``seed``."""
        if not self.external:
            self.env.reset(seed=int(seed))
        self._quiet_env()
        self.time = 0.0
        self.route_progress = 0.0
        self._build_map(np.random.default_rng([int(seed), 0x4857]))

    def _quiet_env(self) -> None:
        # highway-env rebuilds its observation at every reset; ours replaces it
        base = self.env.unwrapped
        if not isinstance(base.observation_type, _NullObservation):
            base.observation_type = _NullObservation(base.observation_space)

    def step(self, ego_action: Any = None) -> None:
        """Advance 0.1 s (one highway-env policy step).

        Args:
            ego_action: ``None`` (autopilot: highway-env's ``IDLE``, which follows
                the planned route; in continuous mode, coast straight), a meta-action
                name from :data:`META_ACTIONS` (meta mode), or ``(accel [m/s^2],
                steer [rad])`` with positive steering to the left.
        """
        if not self.external:
            self._limit_brakes()
            self.env.step(self._to_env_action(ego_action))
        self.time += self.dt
        self.route_progress += self._lane_progress(self.ego_vehicle, self.dt)

    def _limit_brakes(self) -> None:
        """Cap the ego's meta-action braking at ``brake_decel`` (highway-env's speed
        controller brakes at up to ``KP_A * DELTA_SPEED``, ~8 m/s^2 for one SLOWER)."""
        limit = float(self.config["brake_decel"])
        ego = self.ego_vehicle
        if limit <= 0 or not hasattr(ego, "speed_control") or "speed_control" in vars(ego):
            return
        ego.speed_control = functools.partial(_limited_speed_control, type(ego).speed_control,
                                              ego, limit)

    def _to_env_action(self, ego_action: Any) -> Any:
        base = self.env.unwrapped
        at = base.action_type
        if hasattr(at, "actions_indexes"):  # discrete meta-actions
            name = "IDLE" if ego_action is None else ego_action
            if not isinstance(name, str):
                raise ValueError("highway scene in meta mode takes a meta-action name, "
                                 f"got {ego_action!r}")
            if name not in at.actions_indexes:
                raise ValueError(f"meta-action {name!r} not available; "
                                 f"choose from {sorted(at.actions_indexes)}")
            return at.actions_indexes[name]
        accel, steer = (0.0, 0.0) if ego_action is None else (float(v) for v in ego_action)
        lo_a, hi_a = at.acceleration_range
        lo_s, hi_s = at.steering_range
        # highway-env's steering is counter-clockwise in its (mirrored) frame
        norm = [2 * (accel - lo_a) / (hi_a - lo_a) - 1, 2 * (-steer - lo_s) / (hi_s - lo_s) - 1]
        return np.clip(np.asarray(norm, np.float32), -1, 1)[: at.space().shape[0]]

    @staticmethod
    def _lane_progress(vehicle: Any, dt: float) -> float:
        """Distance [m] covered along the current lane's direction in ``dt``."""
        lane = getattr(vehicle, "lane", None)
        if lane is None:
            return float(vehicle.speed * dt)
        s, _ = lane.local_coordinates(vehicle.position)
        return float(vehicle.speed * dt * np.cos(vehicle.heading - lane.heading_at(s)))

    # -- map -------------------------------------------------------------------------
    def _build_map(self, rng: np.random.Generator) -> None:
        base = self.env.unwrapped
        lanes = base.road.network.lanes_list()
        pts = mirror(np.concatenate([  # centre-lines every ~2 m
            lane_points(ln, np.linspace(0.0, ln.length, int(ln.length // 2) + 2),
                         np.zeros(1))[:, 0]
            for ln in lanes]))
        margin, res = self.config["margin"], self.config["resolution"]
        lo = pts.min(axis=0) - margin
        hi = pts.max(axis=0) + margin
        ego = self.ego_pose[:2]
        cap = self.config["max_extent"]
        lo = np.maximum(lo, ego - cap)
        hi = np.minimum(hi, ego + cap)
        bounds = (float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1]))
        raster = rasterise_lanes(lanes, bounds, res)
        origin = (bounds[0], bounds[2])
        buildings = place_buildings(raster, origin, res, self.config["buildings"], rng)
        self.map = WorldMap(raster=raster, origin=origin, resolution=res, buildings=buildings,
                            lanes=None, meta={"source": "highway-env",
                                              "scene": type(base).__name__,
                                              "mirrored_y": True})

    # -- state -----------------------------------------------------------------------
    @property
    def ego_vehicle(self) -> Any:
        """highway-env's controlled vehicle."""
        return self.env.unwrapped.vehicle

    @property
    def ego_pose(self) -> np.ndarray:
        v = self.ego_vehicle
        return np.array([v.position[0], -v.position[1], -v.heading], np.float64)

    @property
    def ego_speed(self) -> float:
        return float(self.ego_vehicle.speed)

    @property
    def collision(self) -> bool:
        return bool(self.ego_vehicle.crashed)

    @property
    def off_road(self) -> bool:
        return not bool(self.ego_vehicle.on_road)

    @property
    def route_done(self) -> bool:
        """The ego reached its destination (scenes with ``has_arrived``)."""
        base = self.env.unwrapped
        return bool(base.has_arrived(base.vehicle)) if hasattr(base, "has_arrived") else False

    @property
    def agents(self) -> Agents:
        base = self.env.unwrapped
        ego = base.vehicle
        vehicles = [v for v in base.road.vehicles if v is not ego]
        # landmarks (goal markers) are not physical
        objs = vehicles + [o for o in base.road.objects if getattr(o, "collidable", True)
                           and type(o).__name__ != "Landmark"]
        if not objs:
            return Agents.empty()
        n = len(objs)
        parked = np.arange(n) >= len(vehicles)
        return Agents(
            xy=mirror(np.array([o.position for o in objs], np.float64)),
            yaw=-np.array([o.heading for o in objs], np.float64),
            speed=np.abs(np.array([o.speed for o in objs], np.float64)),
            length=np.array([o.LENGTH for o in objs], np.float64),
            width=np.array([o.WIDTH for o in objs], np.float64),
            kind=np.full(n, AgentKind.CAR, np.uint8),
            parked=parked,
        )
