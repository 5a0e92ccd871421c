"""``DSTGrid-v0`` and its variants: driving on Dempster-Shafer perception grids."""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from dstenv.config import ConfigError, Validated, build_config
from dstenv.envs.actions import action_mode, default_action_config, highway_settings
from dstenv.envs.info import INFO_SECTION, step_info
from dstenv.envs.navigation import ego_vector, navigation_spaces, route_points
from dstenv.envs.observation import SECTION as OBSERVATION_SECTION
from dstenv.envs.observation import observation_mode
from dstenv.envs.render import HumanWindow, render_frame
from dstenv.envs.rewards import (GIVE_WAY, GiveWayWatch, StepOutcome, default_reward_config,
                                  reward_terms)
from dstenv.frame import Frame
from dstenv.grid import relative_pose
from dstenv.pipeline import Pipeline, WorldSource
from dstenv.pipeline import default_config as pipeline_config

__all__ = ["DSTGridEnv"]

_ENV_SECTIONS = ("observation", "action", "reward", "info")


class DSTGridEnv(gym.Env):
    """Drive through a 2-D city seen only through an occlusion-aware perception grid.

    ## Description

    Each step (0.1 s, one LIDAR revolution) the world advances, a 2-D LIDAR on the
    ego sweeps (occluded by buildings and road users), the sweep is ray-cast into a
    free/occupied/unknown sensor grid, the map is cut into a GIS grid, and a
    Dempster-Shafer filter (Itkina & Kochenderfer) fuses both into a perception
    grid over (navigable, non_navigable, building, static, moving): the agent's view,
    ego-centred, forward up. What hides behind a building stays unknown.

    The world is dstenv's procedural city (``source = "city"``, scenario files in
    ``scenarios/``) or a highway-env scene (``source = "highway"``). Configure with
    ``gym.make(id, config={...})`` (merged over :meth:`default_config`, unknown keys
    rejected) or from a reset on with ``reset(options={"config": {...}})`` (kept).

    ## Observation Space

    ``config["observation"]["type"]`` (:mod:`dstenv.envs.observation`), for an
    ``H x W`` grid (``config["grid"]``: default 256 x 256 cells of 0.33 m):

    * ``"image"`` (default of the paper-size ids): ``Box(0, 255, (4, H, W), uint8)``,
      ``round(255 * BetP)`` of navigable, building, static, moving (non_navigable =
      the rest). Ready for stable-baselines3 ``CnnPolicy`` (needs H, W >= 36).
    * ``"pignistic"``: ``Box(0, 1, (5, H, W), float32)``, BetP over the 5 classes.
    * ``"fcn10"``: ``Box(0, 1, (10, H, W), float32)``, BetP at t and t-1.
    * ``"masses"``: ``Box(0, 1, (32, H, W), float32)``, the raw masses.
    * ``"dict"`` (default of the RL ids): ``Dict(grid=<the "grid" mode, default
      image>, ego=Box(-1, 1, (10,)), route=Box(-1, 1, (2 K,)))``: the ego's speed,
      acceleration, steering, target speed, distance to the next junction, its
      control (one-hot) and signal state, and the next ``route_points`` route points
      ``route_spacing`` m apart in the ego frame (:mod:`dstenv.envs.navigation`).
      stable-baselines3's ``MultiInputPolicy`` takes it as is.

    ## Action Space

    ``config["action"]["type"]`` (:mod:`dstenv.envs.actions`); the space depends on
    the type alone, ``get_action_meanings()`` names the actions:

    * ``"discrete"`` (default): ``Discrete(5)`` = ``0 SLOWER, 1 IDLE, 2 FASTER,
      3 LEFT, 4 RIGHT``. SLOWER / FASTER step a target speed through
      ``target_speeds`` (default 0, 4.5, 9 m/s), braking at most ``brake_decel``.
      City: LEFT / RIGHT choose the turn at the next junction (no effect where it has
      none) while the world's route-following steering (the autopilot's rule) drives
      the planned route. highway-env scenes: LEFT / RIGHT change lane.
    * ``"speed"``: ``Discrete(3)`` = SLOWER, IDLE, FASTER (the route fixes the turns;
      ``DSTGrid-Occluded-v0``).
    * ``"continuous"``: ``Box(-1, 1, (2,), float32)``, (acceleration, steering)
      scaled by ``max_accel`` [m/s^2] and ``max_steer`` [rad], positive = left.
    * ``"autopilot"``: ``Discrete(1)``: the world's own driver (privileged: it reads
      the ground truth), a reference for baselines.

    ## Rewards

    The sum of the weighted terms of ``config["reward"]``, each also reported in
    ``info["rewards"]``: ``progress`` (per metre along the route), ``speed``
    (``min(v / target_speed, 1)`` per step), ``collision`` and ``off_road`` (once,
    negative), ``hard_brake`` (per step decelerating harder than
    ``hard_brake_threshold``), ``arrived`` (once, scenes with a destination),
    ``junction_speed`` (per step, the speed above ``junction_speed_limit`` while the
    next junction on the route is within ``junction_range`` and not green; off by
    default: a shaping term that states the rule driver's junction rule), ``give_way``
    (once, on entering a yield or stop junction without having slowed to
    ``give_way_speed`` within ``give_way_range`` of its entry: the traffic rule broken
    by not giving way; off by default).

    ## Starting State

    A new world from the episode seed (drawn from ``self.np_random``): new city or
    scene, traffic and ego start. With ``world.map.pool = N`` the city is one of N
    maps generated once (Procgen's ``num_levels``), for fast resets and to measure
    generalisation to unseen maps. The filter starts from total ignorance, so the first
    observation holds one sweep.

    ## Episode End

    Terminated on a collision, on leaving the road, or on arrival at the route's end
    (highway-env scenes with a destination). Truncated by the ``TimeLimit`` of the
    registration (``max_episode_steps``, counted in env steps: with ``action.repeat =
    r`` an env step is r world steps of 0.1 s, rewards summed over them). A step after
    ``terminated=True`` raises: call ``reset()``.

    ## Info

    ``sensor`` (H, W) uint8 (0 unknown, 1 free, 2 occupied), ``gis`` (H, W) uint8
    (``MapClass``), ``ego_pose`` (3,) float64, ``ego_speed`` [m/s], ``time`` [s],
    ``seed``, ``collision``, ``off_road``, ``arrived``, ``rewards`` (dict); these are
    the step's own arrays, not copies. ``route_progress`` [m] along the route since
    reset, ``is_success`` (no collision, on the road, and arrived or ``info.success_distance``
    m of progress) and ``termination_reason`` (``"collision"``, ``"off_road"``, ``"arrived"``;
    ``"timeout"`` on a step that does not terminate). With ``config["info"]["labels"]``:
    ``labels`` (H, W) uint8 ground truth (``dstenv.dst.CLASSES`` order, occluded cells
    too), ``visible`` (H, W) bool (computed only then: ~15 % of a 256 x 256 step).
    ``info.lidar_points``: ``lidar_points`` (B, 2) float32 ego-frame returns [m] (NaN:
    none). ``info.autopilot`` (city; privileged): ``autopilot_command`` (accel, steer) the
    autopilot would apply now, ``autopilot_action`` the action closest to it.

    ## Arguments

    * ``config``: overrides of :meth:`default_config`.
    * ``scenario``: a scenario name (``dstenv.scenario_files.list_scenarios()``) or TOML path.
    * ``preset``: the registered variant's settings (a partial config).
      Precedence: :meth:`default_config` < ``scenario`` < ``preset`` < ``config``, so
      ``gym.make("DSTGrid-Continuous-v0", config={"grid": ...})`` keeps the variant.
    * ``world``: an existing world source to drive (advanced use).
    * ``render_mode``: ``"rgb_array"`` (perception grid beside the ground truth) or
      ``"human"`` (the same in a pygame window).

    ## Registered ids

    =========================== ==========================================================
    ``DSTGrid-v0``              default city, 256 x 256 x 0.33 m grid (the paper's)
    ``DSTGrid-Dense-v0``        scenario ``dense`` (downtown: tall blocks, heavy traffic)
    ``DSTGrid-Suburb-v0``       scenario ``suburb``
    ``DSTGrid-Parking-v0``      scenario ``parking`` (parked cars everywhere)
    ``DSTGrid-OSM-v0``          scenario ``osm`` (a real OpenStreetMap extract)
    ``DSTGrid-RL-v0``           default city, RL-sized grid 84 x 84 x 1.0 m (same 84 m
                                view), ``"dict"`` observation (as every id below)
    ``DSTGrid-Continuous-v0``   as ``DSTGrid-RL-v0`` with (acceleration, steering) actions
    ``DSTGrid-Occluded-v0``     occlusion task, RL-sized, speed actions: junctions with
                                cross traffic hidden by buildings, parked cars along
                                the route and pedestrians stepping out; see below
    ``DSTGrid-Highway-v0``      highway-env ``intersection-v1`` scene with buildings,
                                RL-sized grid, highway-env meta-actions
    =========================== ==========================================================

    ``DSTGrid-Occluded-v0``: the world's ``task`` section places cars on the side streets
    of the ego's next junctions, parked cars along its route and pedestrians about to
    cross, hidden by corner buildings until late. Collisions cost 10: a policy that reads
    the grid's unknown regions slows before blind junctions; one that does not collides.

    ## Version History

    * v0: initial version; ``"dict"`` observation on the RL ids, ``"speed"`` actions on
      ``DSTGrid-Occluded-v0``, episode outcome in ``info``, ``info.labels`` opt-in.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 10}

    def __init__(
        self,
        config: Mapping[str, Any] | None = None,
        render_mode: str | None = None,
        scenario: str | None = None,
        preset: Mapping[str, Any] | None = None,
        world: WorldSource | None = None,
    ) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']}, "
                             f"got {render_mode!r}")
        self.render_mode = render_mode
        if world is not None and not callable(getattr(world, "step", None)):
            raise TypeError(f"world: a world source object (reset, step, map, ...), got "
                            f"{world!r}; to pick one by name use config={{'source': ...}}")
        self.scenario = scenario
        self.config = build_config(scenario, ("preset", preset), ("config", config),
                                   defaults=self.default_config())
        self._user_world = world
        self._world = world
        self._window: HumanWindow | None = None
        self._frame: Frame | None = None
        self._ended: str | None = None  # the termination reason once an episode ended
        self._give_way = GiveWayWatch()
        self._last_info: dict[str, Any] = {}
        self._configure()

    @classmethod
    def default_config(cls) -> dict[str, Any]:
        """Every setting, units in comments: the pipeline's sections plus
        ``observation``, ``action``, ``reward`` and ``info``."""
        cfg = pipeline_config()
        cfg.update({
            "observation": OBSERVATION_SECTION.defaults(),
            "action": default_action_config(),
            "reward": default_reward_config(),
            "info": INFO_SECTION.defaults(),
        })
        return cfg

    # -- configuration ------------------------------------------------------------------
    _STATE = ("config", "_obs_name", "_grid_mode", "_action", "pipeline", "observation_space",
              "action_space", "_world")

    def _configure(self, cfg: Mapping[str, Any] | None = None) -> None:
        """Build the pipeline and spaces for ``cfg`` (default ``self.config``); every
        attribute is assigned only after everything was built."""
        cfg = self.config if cfg is None else cfg
        obs_cfg = cfg["observation"]
        obs_name = obs_cfg["type"]
        mode = observation_mode(obs_cfg["grid"] if obs_name == "dict" else obs_name)
        action = action_mode(cfg["action"]["type"])
        pipe_cfg = {k: copy.deepcopy(v) for k, v in cfg.items() if k not in _ENV_SECTIONS}
        pipe_cfg["highway"].update(highway_settings(cfg))  # refuses what a world cannot take
        pipe_cfg["frame"]["masses"] = pipe_cfg["frame"]["masses"] or mode.needs_masses
        # ground truth only when shown (info.labels) or drawn (render)
        pipe_cfg["frame"]["labels"] = bool(cfg["info"]["labels"] or self.render_mode)
        pipe_cfg["frame"]["lidar_points"] = (pipe_cfg["frame"]["lidar_points"]
                                             or cfg["info"]["lidar_points"])
        pipeline = Pipeline(Validated(pipe_cfg), world=self._user_world)
        grid_space = mode.space(pipeline.spec.shape)
        observation_space: gym.Space = (
            spaces.Dict({"grid": grid_space, **navigation_spaces(obs_cfg["route_points"])})
            if obs_name == "dict" else grid_space)
        action_space = action.space(cfg["action"], cfg["source"])
        self.config, self._obs_name, self._grid_mode, self._action = cfg, obs_name, mode, action
        self.pipeline, self._world = pipeline, self._user_world
        self.observation_space, self.action_space = observation_space, action_space

    def get_action_meanings(self) -> list[str]:
        """The meaning of each discrete action, by index (Atari's convention).

        Raises:
            TypeError: the action space is continuous.
        """
        if not self._action.names:
            raise TypeError(f"get_action_meanings: action type {self._action.name!r} is "
                            "continuous (acceleration, steering)")
        return list(self._action.names)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        saved = None
        if options is not None and not isinstance(options, Mapping) or set(options or ()) - {
                "config"}:  # a list was 'unhashable', a string 'unknown key c'
            raise ConfigError(f"reset options: a dict of the one key 'config', got {options!r}")
        if options:
            if options.get("config"):
                # transactional: validate and build first; restore all if the new
                # configuration fails to build or to start its first episode
                cfg = build_config(None, ("options.config", options["config"]),
                                   defaults=self.config)
                saved = {k: getattr(self, k) for k in self._STATE}
        episode_seed, started = int(self.np_random.integers(2**31 - 1)), False
        try:
            if saved is not None:
                self._configure(cfg)
                new = (self.observation_space, self.action_space)
                if new != (saved["observation_space"], saved["action_space"]):
                    raise ConfigError(
                        "reset(options={'config': ...}): the change alters the observation or "
                        f"action space ({saved['observation_space']} -> {new[0]}, "
                        f"{saved['action_space']} -> {new[1]}); spaces are fixed once an env "
                        "exists (vector envs and policies rely on them): build a new env "
                        "with gym.make(id, config=...) instead")
            started = True  # from here on the running episode is gone
            self._frame = self.pipeline.reset(episode_seed)
            self._ended = None
            self._world = self.pipeline.world
            self._controller = self._action.controller(self.config["action"], self._world,
                                                       self.config["source"])
            self._accel = self._progress = 0.0
            self._give_way.reset()
            zero = StepOutcome(0.0, self._world.ego_speed, 0.0, False, False)
            info = self._info(reward_terms(zero, self.config["reward"]), False)
        except Exception:
            for k, v in (saved or {}).items():  # the old configuration again
                setattr(self, k, v)
            if started:  # its episode was replaced: step() asks for a reset first
                self._frame = None
            raise
        if self.render_mode == "human":
            self.render()
        return self._observation(), info

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if self._frame is None:
            raise RuntimeError("DSTGridEnv.step: call reset() first")
        if self._ended is not None:  # it went on simulating, charging the penalty again
            raise RuntimeError(f"DSTGridEnv.step: the episode has ended ({self._ended}, "
                               "terminated=True); call reset() first")
        if isinstance(self.action_space, spaces.Discrete):
            # an integer or a 0-d array inside the space (-1 was taken as the last action,
            # 99 raised an IndexError)
            scalar = ((isinstance(action, (int, np.integer)) and not isinstance(action, bool))
                      or (isinstance(action, np.ndarray) and action.shape == ()))
            if not (scalar and self.action_space.contains(int(action))):
                raise ValueError(f"DSTGridEnv.step: action {action!r} is not in "
                                 f"{self.action_space} ({', '.join(self.get_action_meanings())})")
        w = self._world
        repeat, held = self.config["action"]["repeat"], self._action.held(action)
        rcfg = self.config["reward"]
        terms: dict[str, float] = {}
        terminated = False
        for k in range(repeat):  # the action once, then held (meta-actions: IDLE)
            prev_pose, prev_speed, prev_time = self._frame.ego_pose, w.ego_speed, w.time
            prev_route = getattr(w, "route_progress", None)
            give_way = rcfg["give_way"] != 0.0 and hasattr(w, "next_junction")
            if give_way:
                before, control, _ = w.next_junction()
                self._give_way.before(before, control in GIVE_WAY, prev_speed, rcfg)
            world_action = self._controller.world_action(action if k == 0 else held)
            self._frame = self.pipeline.step(world_action)
            dt = max(w.time - prev_time, 1e-9)
            if prev_route is not None:
                progress = w.route_progress - prev_route
            else:  # forward displacement when the world has no route
                progress = relative_pose(prev_pose, self._frame.ego_pose)[0]
            arrived = bool(getattr(w, "route_done", False))
            junction, green = float("inf"), False
            if (rcfg["junction_speed"] != 0.0 or give_way) and hasattr(w, "next_junction"):
                junction, _, green = w.next_junction()  # once, for both terms
            entered, slowest = (self._give_way.after(junction) if give_way
                                else (False, float("inf")))
            out = StepOutcome(float(progress), float(w.ego_speed),
                              (prev_speed - w.ego_speed) / dt, bool(w.collision),
                              bool(w.off_road), arrived, float(junction), bool(green),
                              bool(entered), slowest)
            for name, value in reward_terms(out, rcfg).items():
                terms[name] = terms.get(name, 0.0) + value
            terminated = out.collision or out.off_road or arrived
            self._accel = (w.ego_speed - prev_speed) / dt
            self._progress += float(progress)
            if terminated:
                break
        info = self._info(terms, terminated)
        if terminated:
            self._ended = str(info.get("termination_reason") or "terminated")
        if self.render_mode == "human":
            self.render()
        return self._observation(), float(sum(terms.values())), terminated, False, info

    def _observation(self) -> np.ndarray | dict[str, np.ndarray]:
        assert self._frame is not None
        grid = self._grid_mode.build(self._frame)
        if self._obs_name != "dict":
            return grid
        cfg = self.config["observation"]
        target = getattr(self._controller, "target_speed", 0.0)
        return {"grid": grid,
                "ego": ego_vector(self._world, self._accel, target),
                "route": route_points(self._world, self._frame.ego_pose, cfg["route_points"],
                                      cfg["route_spacing"])}

    def _info(self, terms: dict[str, float], terminated: bool) -> dict[str, Any]:
        assert self._frame is not None and self._world is not None
        self._last_info = step_info(self._frame, self._world, terms, self._progress,
                                    terminated, self.config["info"], self._controller)
        return self._last_info

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            gym.logger.warn("render() without render_mode; pass render_mode='rgb_array'")
            return None
        if self._frame is None:
            raise RuntimeError("DSTGridEnv.render: call reset() first")
        info = self._last_info
        reward = sum(info.get("rewards", {}).values())
        text = (f"t={self._frame.time:5.1f} s  v={info.get('ego_speed', 0.0):4.1f} m/s  "
                f"r={reward:+.2f}  seed={self._frame.seed}")
        img = render_frame(self._frame, self.pipeline.spec,
                           self._frame.extras.get("lidar_points"), text)
        if self.render_mode == "rgb_array":
            return img
        if self._window is None:
            self._window = HumanWindow("dstenv " + (self.spec.id if self.spec else "DSTGrid"))
        self._window.show(img)
        return None

    def close(self) -> None:
        if self._window is not None:
            self._window.close()
            self._window = None

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_window"] = None  # a pygame window does not pickle
        return state
