"""Shared pieces of the RL baselines (``ppo_grid.py``, ``rule_based.py``,
``random_policy.py``, ``evaluate.py``): command-line arguments from a dataclass,
environment construction, episode statistics and atomic writes.

Each baseline script stays one readable file (cleanrl style); what they all need
lives here once. The scripts import it as a sibling module (``python
baselines/ppo_grid.py`` puts ``baselines/`` on ``sys.path``).

An episode is scored by :func:`run_episode` into an :class:`EpisodeResult`:

* ``collision`` / ``off_road``: the episode ended on that event;
* ``progress``: metres advanced along the route (``info["route_progress"]``);
* ``success``: the env's ``info["is_success"]`` at the last step: no collision, not
  off the road, and either arrived or advanced at least ``info.success_distance``
  metres (default 100; standing still is not a success).
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import math
import os
import platform
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol, TypeVar

import gymnasium as gym
import numpy as np

import dstenv  # noqa: F401  (registers the DSTGrid-* ids)
from dstenv.io import atomic_write_bytes, atomic_write_text
from dstenv.io import output_file as check_output_file
from runfolder import check_not_run_file

__all__ = [
    "opt", "parse_args", "to_argv", "EnvArgs", "env_config", "check_env_args", "make_env",
    "output_file", "check_once", "Policy",
    "EpisodeResult", "run_episode", "summarize", "report_run",
    "evaluate_policy", "write_results_csv", "ENV_COLUMNS", "env_columns",
    "atomic_write_bytes", "atomic_write_text", "machine_info", "cli",
]

T = TypeVar("T")


# -- arguments -----------------------------------------------------------------------------
def cli(main: Callable[[list[str]], Any], argv: Sequence[str] | None = None) -> None:
    """Run a script's ``main(argv)`` as a command: an expected error (bad flag value,
    config error, missing or unreadable file) is one line on stderr and exit status 2,
    as with ``dstenv``; anything else is a bug and keeps its traceback."""
    from dstenv.cli import EXPECTED_ERRORS, one_line

    try:
        main(list(sys.argv[1:] if argv is None else argv))
    except EXPECTED_ERRORS as exc:
        print(f"{Path(sys.argv[0]).name}: error: {one_line(exc)}", file=sys.stderr)
        raise SystemExit(2) from None


def opt(default: Any, help: str) -> Any:  # noqa: A002  (argparse's word)
    """A dataclass field with a help text (lists get a default factory)."""
    if isinstance(default, list):
        return field(default_factory=lambda: list(default), metadata={"help": help})
    return field(default=default, metadata={"help": help})


def parse_args(cls: type[T], argv: Sequence[str] | None = None) -> T:
    """Parse ``argv`` into the dataclass ``cls``: one ``--flag-name`` per field.

    Types come from the field annotations: ``bool`` fields take ``--flag`` /
    ``--no-flag``; ``list[X]`` fields take zero or more values of type ``X``.
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
                                nargs="*", type=typing.get_args(kind)[0])
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


def env_config(args: EnvArgs, overrides: dict[str, Any] | None = None) -> dict[str, Any]:
    """The ``config=`` of ``gym.make``: ``--env-config`` merged over ``overrides``.

    Raises:
        ValueError: ``--env-config`` is not a JSON object.
    """
    try:
        cfg = json.loads(args.env_config) if args.env_config else {}
    except json.JSONDecodeError as exc:
        raise ValueError(f"--env-config: not valid JSON ({exc})") from None
    if not isinstance(cfg, dict):
        raise ValueError(f"--env-config: expected a JSON object, got {type(cfg).__name__}")
    return _merge(overrides or {}, cfg)


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for k, v in over.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def output_file(path: str, flag: str, suffix: str = ".csv") -> None:
    """:func:`dstenv.io.output_file` of an optional output (``""``: none) that is no file
    of a training run (:func:`runfolder.check_not_run_file`) and whose name does not
    promise another format than its ``suffix`` (``--csv r.json`` replaced a JSON file)."""
    if path:
        check_not_run_file(path, flag)
        other = {".csv": ".json", ".json": ".csv"}.get(suffix)
        if Path(path).suffix.lower() == other:
            raise ValueError(f"{flag} {path}: the file is {suffix[1:].upper()}; give a name "
                             f"ending in {suffix}")
        check_output_file(path, flag)


def check_once(paths: Sequence[str], flag: str, why: str = "") -> None:
    """Refuse a path given twice under any spelling (``./x``, ``a/../x``, a symlink).

    Raises:
        ValueError: ``FLAG PATH is given twice (as OTHER)`` and ``why``.
    """
    seen: dict[Path, str] = {}
    for path in paths:
        key = Path(path).resolve()
        if key in seen:
            raise ValueError(f"{flag}: {path} is given twice (as {seen[key]}){why}")
        seen[key] = path


def check_ranges(items: Sequence[tuple]) -> None:
    """``(flag, value, lo[, hi])`` each: refuse a value outside ``[lo, hi]`` (NaN too),
    before any env is built."""
    for flag, value, lo, *hi in items:
        top = hi[0] if hi else math.inf
        if not lo <= value <= top:
            raise ValueError(f"{flag} {value}: must be "
                             + (f"at least {lo}" if top == math.inf else f"in [{lo}, {top}]"))


def check_env_args(args: EnvArgs) -> None:
    """The environment arguments, checked before any env is built (a subprocess env
    would report a bad one as a traceback).

    Raises:
        ValueError: an id that is not a registered DSTGrid one, a negative time limit.
    """
    import dstenv.envs  # noqa: F401  (registers the ids)

    known = sorted(k for k in gym.registry if k.startswith("DSTGrid-"))
    if args.env_id not in known:
        raise ValueError(f"--env-id {args.env_id}: not a registered DSTGrid id; choose "
                         f"from {', '.join(known)}")
    if args.max_episode_steps < 0:
        raise ValueError(f"--max-episode-steps {args.max_episode_steps}: must be at least 0 "
                         "(0: the registration's)")
    world = env_config(args).get("world")
    if isinstance(world, dict) and isinstance(world.get("map"), dict) and "pool" in world["map"]:
        raise ValueError("--env-config world.map.pool: the drivers are scored and tuned on a "
                         "fresh map per seed (a pool would replay training maps); ppo_grid.py "
                         "takes its training maps as --map-pool")


def make_env(args: EnvArgs, overrides: dict[str, Any] | None = None, monitor: bool = False,
             wrap: Callable[[gym.Env], gym.Env] | None = None) -> gym.Env:
    """Build one environment with ``gym.make`` (registered id, its default observation).

    Args:
        args: environment arguments.
        overrides: config the baseline itself sets (e.g. ``{"action": {"type":
            "autopilot"}}``), under ``--env-config``.
        monitor: wrap with stable-baselines3's ``Monitor`` (episode statistics with
            ``is_success``, ``collision``, ``off_road`` and ``route_progress`` in
            ``info["episode"]``).
        wrap: applied to the env before ``Monitor`` (e.g. :func:`residual.wrap`).
    """
    check_env_args(args)
    kwargs: dict[str, Any] = {"config": env_config(args, overrides)}
    if args.max_episode_steps > 0:
        kwargs["max_episode_steps"] = args.max_episode_steps
    env = gym.make(args.env_id, **kwargs)
    if wrap is not None:
        env = wrap(env)
    if monitor:
        from stable_baselines3.common.monitor import Monitor

        env = Monitor(env, info_keywords=("is_success", "collision", "off_road",
                                          "route_progress"))
    return env


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


def run_episode(env: gym.Env, policy: Policy, seed: int) -> EpisodeResult:
    """Drive one episode of ``env`` (built by :func:`make_env`) from ``seed``; the env's
    ``info`` says whether it succeeded (``is_success``, ``info.success_distance``)."""
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
    success = bool(info["is_success"])
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
                    log: Callable[[EpisodeResult], Any] | None = None) -> list[EpisodeResult]:
    """Run ``policy`` on ``env`` (from :func:`make_env`) for one episode per seed;
    ``log`` sees each result as it finishes."""
    results = []
    for seed in seeds:
        res = run_episode(env, policy, int(seed))
        if log is not None:
            log(res)
        results.append(res)
    return results


#: the env of an episode, in every row of a results CSV (compare.py pairs only alike)
ENV_COLUMNS = ("env_id", "env_config", "max_episode_steps")


def env_columns(args: EnvArgs) -> list[Any]:
    """:data:`ENV_COLUMNS` of ``args``: the id, the ``--env-config`` as canonical JSON
    (keys sorted, no spaces; ``{}`` for none) and the time limit (0: the registration's)."""
    return [args.env_id, json.dumps(env_config(args), sort_keys=True, separators=(",", ":")),
            args.max_episode_steps]


def write_results_csv(path: str | Path, runs: Sequence[tuple[str, Sequence[EpisodeResult]]],
                      env: EnvArgs) -> None:
    """Write the episodes of ``(policy name, results)`` pairs, all driven in ``env``'s
    environment, as one CSV (atomically)."""
    import io

    buf = io.StringIO()
    writer = csv.writer(buf)
    writer.writerow(["policy"] + [f.name for f in dataclasses.fields(EpisodeResult)]
                    + list(ENV_COLUMNS))
    where = env_columns(env)
    for name, results in runs:
        writer.writerows([name, *dataclasses.astuple(r), *where] for r in results)
    atomic_write_text(path, buf.getvalue())


def report_run(name: str, results: list[EpisodeResult], args: Any) -> dict[str, float]:
    """Print one policy's summary; with ``args.csv`` also write its episodes there
    (``args``: the script's arguments, an :class:`EnvArgs`); return the summary."""
    summary = summarize(results)
    print(name, {k: round(v, 3) for k, v in summary.items()})
    if args.csv:
        write_results_csv(args.csv, [(name, results)], args)
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
