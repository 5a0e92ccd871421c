"""Shared pieces of the RL baselines (``ppo_grid.py``, ``rule_based.py``,
``random_policy.py``, ``evaluate.py``): command-line arguments from a dataclass,
environment construction, episode statistics and atomic writes.

Each baseline script stays one readable file (cleanrl style); what they all need
lives here once. The scripts import it as a sibling module (``python
baselines/ppo_grid.py`` puts ``baselines/`` on ``sys.path``).

An episode is scored by :func:`run_episode` into an :class:`EpisodeResult`:

* ``collision`` / ``off_road``: the episode ended on that event;
* ``progress``: metres advanced along the route (the env's ``progress`` reward
  term divided by its weight);
* ``success``: no collision, not off the road, and either arrived or advanced at
  least ``success_distance`` metres (standing still is not a success).
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import os
import platform
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol, TypeVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

import dstenv  # noqa: F401  (registers the DSTGrid-* ids)
from dstenv.io import atomic_write_bytes, atomic_write_text

__all__ = [
    "opt", "parse_args", "to_argv", "EnvArgs", "env_config", "make_env", "EGO_STATES",
    "EgoStateObservation",
    "RouteProgress", "Policy", "EpisodeResult", "run_episode", "summarize", "report_run",
    "evaluate_policy", "write_results_csv",
    "atomic_write_bytes", "atomic_write_text", "machine_info",
]

T = TypeVar("T")

#: ``--ego-state`` values: what :class:`EgoStateObservation` adds beside the grid.
EGO_STATES = ("none", "speed", "speed+route")


# -- arguments -----------------------------------------------------------------------------
def opt(default: Any, help: str) -> Any:  # noqa: A002  (argparse's word)
    """A dataclass field with a help text (lists get a default factory)."""
    if isinstance(default, list):
        return field(default_factory=lambda: list(default), metadata={"help": help})
    return field(default=default, metadata={"help": help})


def parse_args(cls: type[T], argv: Sequence[str] | None = None) -> T:
    """Parse ``argv`` into the dataclass ``cls``: one ``--flag-name`` per field.

    Types come from the field annotations: ``bool`` fields take ``--flag`` /
    ``--no-flag``; ``list[X]`` fields take one or more values of type ``X``.
    """
    import typing

    hints = typing.get_type_hints(cls)
    parser = argparse.ArgumentParser(description=(cls.__doc__ or "").strip().split("\n")[0])
    for f in dataclasses.fields(cls):  # type: ignore[arg-type]
        default = f.default if f.default is not dataclasses.MISSING else f.default_factory()
        flag = "--" + f.name.replace("_", "-")
        helptext = f"{f.metadata.get('help', '')} (default: {default!r})"
        kind = hints[f.name]
        if kind is bool:
            parser.add_argument(flag, dest=f.name, default=default, help=helptext,
                                action=argparse.BooleanOptionalAction)
        elif typing.get_origin(kind) is list:
            parser.add_argument(flag, dest=f.name, default=default, help=helptext,
                                nargs="+", type=typing.get_args(kind)[0])
        else:
            parser.add_argument(flag, dest=f.name, default=default, help=helptext, type=kind)
    return cls(**vars(parser.parse_args(argv)))


def to_argv(args: Any) -> list[str]:
    """The command-line flags that rebuild the dataclass ``args`` (non-defaults only)."""
    argv: list[str] = []
    for f in dataclasses.fields(args):
        default = f.default if f.default is not dataclasses.MISSING else f.default_factory()
        value = getattr(args, f.name)
        if value == default:
            continue
        flag = "--" + f.name.replace("_", "-")
        if isinstance(value, bool):
            argv.append(flag if value else "--no-" + flag[2:])
        elif isinstance(value, list):
            argv += [flag, *map(str, value)]
        else:
            argv += [flag, str(value)]
    return argv


@dataclass
class EnvArgs:
    """The environment every baseline drives (shared arguments)."""

    env_id: str = opt("DSTGrid-Occluded-v0", "registered DSTGrid-* id")
    env_config: str = opt("", "JSON overrides of the env config, e.g. "
                              "'{\"grid\": {\"height\": 40, \"width\": 40}}'")
    max_episode_steps: int = opt(0, "episode time limit [steps]; 0 = the registration's")


def env_config(args: EnvArgs, observation: str | None = None) -> dict[str, Any]:
    """The ``config=`` of ``gym.make``: ``--env-config`` plus the observation type.

    Raises:
        ValueError: ``--env-config`` is not a JSON object.
    """
    try:
        cfg = json.loads(args.env_config) if args.env_config else {}
    except json.JSONDecodeError as exc:
        raise ValueError(f"--env-config: not valid JSON ({exc})") from None
    if not isinstance(cfg, dict):
        raise ValueError(f"--env-config: expected a JSON object, got {type(cfg).__name__}")
    if observation is not None:
        cfg = {**cfg, "observation": {**cfg.get("observation", {}), "type": observation}}
    # the baselines choose speed only: the route fixes the turns (Discrete(3))
    return {**cfg, "action": {"turns": False, **cfg.get("action", {})}}


def make_env(args: EnvArgs, observation: str | None = None, ego_state: str = "none",
             monitor: bool = False, world: Any = None) -> gym.Env:
    """Build one environment: ``gym.make`` + :class:`RouteProgress` (+ ego state, Monitor).

    Args:
        args: environment arguments.
        observation: ``config["observation"]["type"]``; ``None`` keeps the env's.
        ego_state: one of :data:`EGO_STATES`: ``"none"`` keeps the env's observation;
            ``"speed"`` / ``"speed+route"`` wrap it in :class:`EgoStateObservation`.
        monitor: wrap with stable-baselines3's ``Monitor`` (episode statistics
            including ``collision``, ``off_road`` and ``route_progress`` in
            ``info["episode"]``).
        world: a world source for the env's ``world=`` argument (``None``: the env
            builds its own).
    """
    if ego_state not in EGO_STATES:
        raise ValueError(f"ego state: expected one of {EGO_STATES}, got {ego_state!r}")
    kwargs: dict[str, Any] = {"config": env_config(args, observation)}
    if args.max_episode_steps > 0:
        kwargs["max_episode_steps"] = args.max_episode_steps
    if world is not None:
        kwargs["world"] = world
    env: gym.Env = RouteProgress(gym.make(args.env_id, **kwargs))
    if ego_state != "none":
        env = EgoStateObservation(env, with_route=ego_state == "speed+route")
    if monitor:
        from stable_baselines3.common.monitor import Monitor

        env = Monitor(env, info_keywords=("collision", "off_road", "route_progress"))
    return env


# -- wrappers ------------------------------------------------------------------------------
class RouteProgress(gym.Wrapper):
    """Adds ``info["route_progress"]``: metres advanced along the route since reset.

    Read from the env's ``progress`` reward term divided by its weight; when that
    weight is 0, the path length of ``info["ego_pose"]`` is used instead.
    """

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self._weight = float(env.unwrapped.config["reward"]["progress"])
        self._total = 0.0
        self._pose: np.ndarray | None = None

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        self._total, self._pose = 0.0, np.asarray(info["ego_pose"], np.float64)
        info["route_progress"] = 0.0
        return obs, info

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        pose = np.asarray(info["ego_pose"], np.float64)
        if self._weight != 0.0:
            self._total += info["rewards"]["progress"] / self._weight
        elif self._pose is not None:
            self._total += float(np.hypot(*(pose[:2] - self._pose[:2])))
        self._pose = pose
        info["route_progress"] = self._total
        return obs, reward, terminated, truncated, info


class EgoStateObservation(gym.Wrapper):
    """Observation ``{"grid": env observation, "ego": (1 + 2 K,) float32}``.

    One ego-centred grid shows neither how fast the ego drives nor where its route
    goes at the next junction, and the discrete meta-actions step a target speed
    along that route. The ``ego`` vector gives both, as a navigation system would:

    * ``ego[0]``: ego speed / ``world.ego.max_speed``, clipped to [0, 1];
    * ``ego[1:]`` (``with_route``): the route ``route_step, 2 route_step, ...,
      K route_step`` metres ahead, as ego-frame ``(x, y)`` pairs divided by
      ``K route_step`` (so in [-1, 1]), from the world's ``route_polyline``;
      zeros for worlds without a route (highway-env scenes).

    Args:
        env: the env (``DSTGridEnv`` inside).
        with_route: append the route points.
        route_points: K.
        route_step: [m] spacing of the route points.
    """

    def __init__(self, env: gym.Env, with_route: bool = True, route_points: int = 8,
                 route_step: float = 5.0) -> None:
        super().__init__(env)
        self._scale = float(env.unwrapped.config["world"]["ego"]["max_speed"])
        self._k = route_points if with_route else 0
        self._step = float(route_step)
        self.observation_space = spaces.Dict({
            "grid": env.observation_space,
            "ego": spaces.Box(-1.0, 1.0, (1 + 2 * self._k,), dtype=np.float32),
        })

    def _route(self, info: dict[str, Any]) -> np.ndarray:
        world = self.env.unwrapped.pipeline.world
        ahead = self._k * self._step
        if not hasattr(world, "route_polyline"):
            return np.zeros(2 * self._k, np.float32)
        pts = world.route_polyline(ahead=ahead, spacing=self._step)[1:self._k + 1]
        x, y, yaw = info["ego_pose"]
        d = pts - np.array([x, y])
        c, s = np.cos(yaw), np.sin(yaw)
        local = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]], axis=1)
        return np.clip(local / ahead, -1.0, 1.0).astype(np.float32).reshape(-1)

    def _obs(self, obs: np.ndarray, info: dict[str, Any]) -> dict[str, np.ndarray]:
        v = np.clip(info["ego_speed"] / self._scale, 0.0, 1.0)
        parts = [np.array([v], np.float32)]
        if self._k:
            parts.append(self._route(info))
        return {"grid": obs, "ego": np.concatenate(parts)}

    def reset(self, **kwargs: Any) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        return self._obs(obs, info), info

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        return self._obs(obs, info), reward, terminated, truncated, info


# -- episodes ------------------------------------------------------------------------------
class Policy(Protocol):
    """A driver evaluated by :func:`run_episode`."""

    name: str

    def reset(self, env: gym.Env, seed: int) -> None:
        """Called after ``env.reset(seed=seed)``, before the first :meth:`act`."""

    def act(self, obs: Any, info: dict[str, Any]) -> Any:
        """The action for the current observation and info."""


@dataclass(frozen=True)
class EpisodeResult:
    """One evaluated episode (see the module docstring for the definitions)."""

    seed: int
    episode_return: float
    length: int  # [steps]
    collision: bool
    off_road: bool
    arrived: bool
    progress: float  # [m] along the route
    success: bool


def run_episode(env: gym.Env, policy: Policy, seed: int, success_distance: float = 100.0
                ) -> EpisodeResult:
    """Drive one episode of ``env`` (built by :func:`make_env`) from ``seed``."""
    obs, info = env.reset(seed=seed)
    policy.reset(env, seed)
    total, steps, done = 0.0, 0, False
    while not done:
        obs, reward, terminated, truncated, info = env.step(policy.act(obs, info))
        total += float(reward)
        steps += 1
        done = terminated or truncated
    collision, off_road = bool(info["collision"]), bool(info["off_road"])
    arrived = bool(info.get("arrived", False))
    progress = float(info["route_progress"])
    success = not (collision or off_road) and (arrived or progress >= success_distance)
    return EpisodeResult(seed, total, steps, collision, off_road, arrived, progress, success)


def summarize(results: Sequence[EpisodeResult]) -> dict[str, float]:
    """Rates and means over episodes: ``success``, ``collision``, ``off_road`` (rates in
    [0, 1]), ``return``, ``progress`` [m], ``length`` [steps] and their standard errors
    ``return_se``, ``progress_se``."""
    if not results:
        raise ValueError("summarize: no episodes")
    n = len(results)

    def mean_se(values: list[float]) -> tuple[float, float]:
        a = np.asarray(values, np.float64)
        return float(a.mean()), float(a.std(ddof=1) / np.sqrt(n)) if n > 1 else 0.0

    ret, ret_se = mean_se([r.episode_return for r in results])
    prog, prog_se = mean_se([r.progress for r in results])
    return {
        "episodes": float(n),
        "success": sum(r.success for r in results) / n,
        "collision": sum(r.collision for r in results) / n,
        "off_road": sum(r.off_road for r in results) / n,
        "return": ret, "return_se": ret_se,
        "progress": prog, "progress_se": prog_se,
        "length": float(np.mean([r.length for r in results])),
    }


def evaluate_policy(env: gym.Env, policy: Policy, seeds: Sequence[int],
                    success_distance: float = 100.0,
                    log: Callable[[EpisodeResult], Any] | None = None) -> list[EpisodeResult]:
    """Run ``policy`` on ``env`` (from :func:`make_env`) for one episode per seed;
    ``log`` sees each result as it finishes."""
    results = []
    for seed in seeds:
        res = run_episode(env, policy, int(seed), success_distance)
        if log is not None:
            log(res)
        results.append(res)
    return results


def write_results_csv(path: str | Path,
                      runs: Sequence[tuple[str, Sequence[EpisodeResult]]]) -> None:
    """Write the episodes of ``(policy name, results)`` pairs as one CSV (atomically)."""
    import io

    buf = io.StringIO()
    writer = csv.writer(buf)
    writer.writerow(["policy"] + [f.name for f in dataclasses.fields(EpisodeResult)])
    for name, results in runs:
        writer.writerows([name, *dataclasses.astuple(r)] for r in results)
    atomic_write_text(path, buf.getvalue())


def report_run(name: str, results: list[EpisodeResult], csv: str = "") -> dict[str, float]:
    """Print one policy's summary, optionally write its episodes to ``csv``; return it."""
    summary = summarize(results)
    print(name, {k: round(v, 3) for k, v in summary.items()})
    if csv:
        write_results_csv(csv, [(name, results)])
    return summary


# -- files and machine ---------------------------------------------------------------------
def machine_info() -> dict[str, Any]:
    """Where a run happened: host, CPU model, core count, library versions."""
    import stable_baselines3
    import torch

    cpu = platform.processor()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {
        "host": platform.node(),
        "cpu": cpu,
        "cores": os.cpu_count(),
        "torch_threads": torch.get_num_threads(),
        "python": platform.python_version(),
        "torch": torch.__version__,
        "stable_baselines3": stable_baselines3.__version__,
    }
