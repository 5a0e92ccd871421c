"""``DSTGridObservation``: give any highway-env environment DST perception-grid observations."""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from dstenv.config import build_config
from dstenv.envs.observation import observation_mode
from dstenv.envs.render import render_frame
from dstenv.frame import Frame
from dstenv.pipeline import Pipeline

__all__ = ["DSTGridObservation"]


class DSTGridObservation(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Replace a highway-env env's observation with a DST perception grid.

    The wrapped env keeps its own actions, reward, termination and info; the
    wrapper rasterises its road network (lanes = road, the rest intermediate, with
    seeded buildings off-road so that the LIDAR is occluded), sweeps a LIDAR from
    its controlled vehicle every step, fuses the perception grid and returns it as
    the observation. The grids dataset users need are added to ``info``
    (``sensor``, ``gis``, ``ego_pose``; ``labels`` and ``visible`` with
    ``info.labels``, ``lidar_points`` with ``info.lidar_points``), like
    :class:`~dstenv.envs.DSTGridEnv`.

    The filter assumes one env step per LIDAR sweep; give the env
    ``policy_frequency = simulation_frequency = 10`` for the sensor's 10 Hz (other
    rates work, with larger ego motion between sweeps). highway-env's own
    observation is switched off (it is not computed) to save time.

    Args:
        env: a highway-env environment (``gym.make("intersection-v1")`` ...).
        config: overrides of :meth:`default_config`: the pipeline's sections
            (``grid``, ``lidar``, ``dst``, ``highway`` for the buildings...) plus
            ``observation`` and ``info`` as in :class:`DSTGridEnv`.

    Example:
        >>> env = DSTGridObservation(gym.make("intersection-v1", config={
        ...     "simulation_frequency": 10, "policy_frequency": 10}),
        ...     config={"grid": {"height": 84, "width": 84, "cell_size": 1.0}})
        >>> obs, info = env.reset(seed=0)      # obs: (4, 84, 84) uint8
    """

    def __init__(self, env: gym.Env, config: Mapping[str, Any] | None = None) -> None:
        from dstenv.sim.highway import HighwayWorld

        base = env.unwrapped
        if not (hasattr(base, "road") and hasattr(base, "vehicle")
                and type(base).__module__.startswith("highway_env")):
            raise TypeError(f"DSTGridObservation wraps highway-env environments (e.g. "
                            f"gym.make('intersection-v1')), got {type(base).__name__} from "
                            f"{type(base).__module__}; for dstenv's city use "
                            "gym.make('DSTGrid-v0')")
        gym.utils.RecordConstructorArgs.__init__(self, config=config)
        gym.Wrapper.__init__(self, env)

        self.config = build_config(None, ("config", config), defaults=self.default_config())
        cfg = self.config
        self._obs_name = cfg["observation"]["type"]
        mode = observation_mode(self._obs_name)
        pipe_cfg = {k: copy.deepcopy(v) for k, v in cfg.items() if k not in ("observation", "info")}
        pipe_cfg["source"] = "highway"
        pipe_cfg["frame"]["masses"] = pipe_cfg["frame"]["masses"] or mode.needs_masses
        pipe_cfg["frame"]["labels"] = bool(cfg["info"]["labels"]
                                           or env.unwrapped.render_mode == "rgb_array")
        pipe_cfg["frame"]["lidar_points"] = (pipe_cfg["frame"]["lidar_points"]
                                             or cfg["info"]["lidar_points"])
        world = HighwayWorld(pipe_cfg["highway"], env=env, external=True)
        self.pipeline = Pipeline(pipe_cfg, world=world)
        self.observation_space = mode.space(self.pipeline.spec.shape)
        self._frame: Frame | None = None
        self._seeds = np.random.default_rng()

    @classmethod
    def default_config(cls) -> dict[str, Any]:
        """The pipeline's sections plus ``observation`` and ``info`` (see DSTGridEnv)."""
        from dstenv.envs.dstgrid import DSTGridEnv

        full = DSTGridEnv.default_config()
        return {k: v for k, v in full.items() if k not in ("source", "world", "action", "reward")}

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[np.ndarray, dict[str, Any]]:
        _, info = self.env.reset(seed=seed, options=options)
        if seed is not None:
            self._seeds = np.random.default_rng(seed)
        episode_seed = int(self._seeds.integers(2**31 - 1))
        self._frame = self.pipeline.reset(episode_seed)
        return self._observe(info)

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if self._frame is None:
            raise RuntimeError("DSTGridObservation.step: call reset() first")
        _, reward, terminated, truncated, info = self.env.step(action)
        self._frame = self.pipeline.step()
        obs, info = self._observe(info)
        return obs, reward, terminated, truncated, info

    def _observe(self, info: dict[str, Any]) -> tuple[np.ndarray, dict[str, Any]]:
        f = self._frame
        assert f is not None
        info = dict(info)
        info.update(sensor=f.sensor, gis=f.gis, ego_pose=f.ego_pose)
        if self.config["info"]["labels"]:
            info.update(labels=f.labels, visible=f.visible)
        if self.config["info"]["lidar_points"]:
            info["lidar_points"] = f.extras["lidar_points"]
        return observation_mode(self._obs_name).build(f), info

    def render(self) -> Any:
        """The perception grid beside the ground truth (``rgb_array``), else the env's."""
        if self.render_mode != "rgb_array" or self._frame is None:
            return self.env.render()
        return render_frame(self._frame, self.pipeline.spec,
                            self._frame.extras.get("lidar_points"),
                            f"t={self._frame.time:5.1f} s  seed={self._frame.seed}")
