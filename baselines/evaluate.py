"""Evaluate drivers on a fixed set of seeds and print (optionally write) the results table.

Every policy drives one episode per seed ``--seed .. --seed + --episodes - 1`` of
the same registered env with its default observation (same worlds, same traffic,
a fresh map per seed, none of them a training map): ``random``
(:mod:`random_policy`), ``grid`` (the grid-aware rule driver), ``grid-tuned`` (the
same with its parameters tuned on validation seeds), ``autopilot``
(privileged), ``constant``, ``advice`` and ``cautious`` (privileged teachers; all in
:mod:`rule_based`), and each trained PPO checkpoint
given with ``--checkpoints`` (``model.pt`` state_dicts from :mod:`ppo_grid`, with
their ``model.json`` sidecars; only tensors are loaded); with ``--shield NAME`` each
of them also held back by a rule driver (the slower of the two actions each step). Reported
per policy:
success rate, collision rate, off-road rate, mean return and mean route progress
[m] with standard errors (definitions in :mod:`rl_common`).

The Markdown table, the command that produced it, the training budgets and the
machine are printed; ``--write-readme`` also replaces the block between
``<!-- results:begin -->`` and ``<!-- results:end -->`` of ``--readme`` (written
atomically); without it no file but ``--csv`` is written. Run::

    python baselines/evaluate.py --episodes 100 --checkpoints baselines/checkpoints/ppo_occluded.pt
"""

from __future__ import annotations

import json
import shlex
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from random_policy import RandomPolicy
from rl_common import EnvArgs, EpisodeResult, atomic_write_text, evaluate_policy, machine_info
from rl_common import (
    check_once,
    cli,
    make_env,
    opt,
    output_file,
    parse_args,
    summarize,
    write_results_csv,
)
from rule_based import DRIVERS, check_shield, reference_driver, shielded

BEGIN, END = "<!-- results:begin -->", "<!-- results:end -->"
POLICIES = ("random", *DRIVERS)


@dataclass
class Args(EnvArgs):
    """Evaluate drivers on fixed seeds and write the results table."""

    policies: list[str] = opt(["random", "grid", "autopilot", "constant"],
                              "reference drivers: random | grid | grid-tuned | autopilot | "
                              "constant | advice | cautious")
    checkpoints: list[str] = opt([], "PPO model.pt files from ppo_grid.py")
    constant_action: int = opt(2, "action of the constant driver (city: 2 = FASTER)")
    episodes: int = opt(50, "episodes per policy, one per seed")
    seed: int = opt(10_000, "first evaluation seed (episode k uses seed + k)")
    deterministic: bool = opt(True, "PPO: take the most likely action")
    temperature: float = opt(0.0, "PPO: sample from softmax(logits / T) with T > 0 "
                                  "(seeded per episode; overrides --deterministic); "
                                  "0 = off")
    readme: str = opt("", "Markdown file whose results block --write-readme replaces "
                          "(given explicitly: baselines/README.md's block holds rows "
                          "written by hand)")
    write_readme: bool = opt(False, "replace the results block of --readme (else print only)")
    csv: str = opt("", "write every episode of every policy to this CSV file")
    torch_threads: int = opt(1, "torch CPU threads for the PPO policies")
    shield: str = opt("", "'' (none) | grid | grid-tuned: every policy also drives held "
                          "back by that rule driver, each step the slower of the two speed "
                          "actions (rows '<policy> + shield <name>')")


#: what a ppo_grid.py sidecar holds (and the results table reads)
SIDECAR_KEYS = ("args", "timesteps", "wall_time_s")


class PPOPolicy:
    """A trained PPO policy: ``model.pt`` (state_dict) and its ``model.json`` sidecar."""

    def __init__(self, path: str | Path, deterministic: bool = True,
                 temperature: float = 0.0) -> None:
        if not temperature >= 0.0:
            raise ValueError(f"--temperature: {temperature} must be >= 0 (0 = off)")
        self.path = Path(path)
        if not self.path.is_file():
            raise FileNotFoundError(f"--checkpoints: no such file {self.path}")
        sidecar = self.path.with_suffix(".json")
        if not sidecar.is_file():
            raise FileNotFoundError(f"{self.path}: missing its sidecar {sidecar.name}")
        try:
            self.meta: dict[str, Any] = json.loads(sidecar.read_text())
            extractor = self.meta["args"]["extractor"]
            missing = [k for k in SIDECAR_KEYS if k not in self.meta]
        except (ValueError, KeyError, TypeError):
            missing = ["args"]
        if missing:  # (no 'wall_time_s' failed after every episode had run)
            raise ValueError(f"{sidecar}: not the model.json of a ppo_grid.py run (bad JSON, "
                             f"or no {missing[0]!r}); keep the pair that ppo_grid.py wrote")
        self.deterministic = deterministic
        self.temperature = float(temperature)
        # a warm start saved before PPO took a step is the imitation policy alone
        learner = ("DAgger" if self.meta.get("warm_start") and not self.meta.get("timesteps")
                   else "PPO")
        # ppo_grid.py names every run's weights model.pt: the run folder tells them apart
        stem = self.path.parent.name if self.path.stem == "model" else self.path.stem
        residual = self.meta["args"].get("residual")  # the policy drives on top of a rule
        self.name = f"{learner} {extractor}" + (f" + residual {residual}" if residual else "") \
            + f" ({stem})" + (f" T={self.temperature:g}" if self.temperature > 0 else
                              " sampled" if not deterministic else "")
        self.model: Any = None
        self.rng = np.random.default_rng(0)
        from dstenv.segment.checkpoint import read_weights

        # read before any episode, and kept for make_env (not read a second time)
        self._state = read_weights(self.path, "not a readable policy checkpoint")

    def make_env(self, args: EnvArgs) -> gym.Env:
        """The evaluation env; the policy is rebuilt on its spaces."""
        from ppo_grid import env_wrap, load

        run = self.meta["args"]
        env = make_env(args, wrap=env_wrap(run.get("residual", ""), run.get("critic", "")))
        try:
            self.model, self.meta = load(self.path, env, self._state)
        except Exception:
            env.close()
            raise
        return env

    def reset(self, env: gym.Env, seed: int) -> None:
        self.rng = np.random.default_rng(seed)  # sampled actions repeat per seed

    def probabilities(self, obs: Any) -> np.ndarray:
        """softmax(logits / T) of a ``Discrete(n)`` policy: shape (n,)."""
        import torch

        with torch.no_grad():
            tensor, _ = self.model.policy.obs_to_tensor(obs)
            dist = self.model.policy.get_distribution(tensor).distribution
            if not isinstance(dist, torch.distributions.Categorical):
                raise ValueError(f"--temperature needs a Discrete action space, "
                                 f"{self.path} has {self.meta.get('action_space')}")
            logits = dist.logits[0].double().numpy() / self.temperature
        p = np.exp(logits - logits.max())
        return p / p.sum()

    def act(self, obs: Any, info: dict[str, Any]) -> Any:
        if self.temperature > 0:
            p = self.probabilities(obs)
            return int(self.rng.choice(len(p), p=p))
        action, _ = self.model.predict(obs, deterministic=self.deterministic)
        return int(action) if np.ndim(action) == 0 else action


def _reference(name: str, args: Args) -> tuple[Any, gym.Env]:
    if name == "random":
        return RandomPolicy(), make_env(args)
    if name not in DRIVERS:
        raise ValueError(f"--policies: unknown policy {name!r}; known: {', '.join(POLICIES)}")
    return reference_driver(name, args, args.constant_action)


def _pct(x: float) -> str:
    return f"{100 * x:.0f} %"


def _env_step_count(meta: dict[str, Any]) -> int:
    """Every env step of the training run, a warm start's included (``model.json``'s
    ``env_steps``; ``timesteps`` counts PPO's alone)."""
    return int(meta.get("env_steps", meta["timesteps"]))


def _env_steps(meta: dict[str, Any]) -> str:
    """:func:`_env_step_count` as text, naming the warm start's share."""
    warm = int((meta.get("warm_start") or {}).get("timesteps", 0))
    return f"{_env_step_count(meta):,} steps" + (f" ({warm:,} of them imitation)" if warm else "")


def _budget(meta: dict[str, Any] | None) -> str:
    if meta is None:
        return "-"
    minutes = meta["wall_time_s"] / 60
    return f"{_env_steps(meta)}, {minutes:.{1 if minutes < 10 else 0}f} min"


def results_markdown(rows: list[tuple[str, dict[str, float], dict[str, Any] | None]],
                     args: Args, command: str) -> str:
    """The results block: table, command, seeds, training budgets, machine."""
    lines = [
        f"Env `{args.env_id}`" + (f" with `--env-config '{args.env_config}'`"
                                  if args.env_config else "")
        + f", seeds {args.seed}..{args.seed + args.episodes - 1} (one episode each), "
        "success = the env's `is_success`: no collision, on the road, >= 100 m of route "
        "progress (or arrived).",
        "",
        "| policy | success | collision | off-road | return | progress [m] | length [steps]"
        " | training budget |",
        "|---|---:|---:|---:|---:|---:|---:|---|",
    ]
    for name, s, meta in rows:
        lines.append(f"| {name} | {_pct(s['success'])} | {_pct(s['collision'])} | "
                     f"{_pct(s['off_road'])} | {s['return']:.1f} ± {s['return_se']:.1f} | "
                     f"{s['progress']:.0f} ± {s['progress_se']:.0f} | {s['length']:.0f} | "
                     f"{_budget(meta)} |")
    m = machine_info()
    lines += ["", "Reproduce:", "", "```", command, "```", "",
              f"Evaluated {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())} on "
              f"{m['cpu']} ({m['cores']} cores), torch {m['torch']}, "
              f"stable-baselines3 {m['stable_baselines3']}."]
    for name, _, meta in rows:
        if meta is None:
            continue
        tm = meta["machine"]
        lines += ["", f"Training of {name}: {_env_steps(meta)} in "
                  f"{meta['wall_time_s'] / 60:.1f} min wall time "
                  f"({_env_step_count(meta) / max(meta['wall_time_s'], 1e-9):.0f} steps/s), "
                  f"{tm['cpu']} ({tm['cores']} cores, {tm['torch_threads']} torch threads), "
                  f"finished {meta['finished_utc']} UTC:", "", "```",
                  meta.get("command") or "(command not recorded)", "```"]
    return "\n".join(lines) + "\n"


def _readme_parts(path: str | Path) -> tuple[str, str]:
    """What stays of ``path`` around its results block (a new file: only the block).

    Raises:
        ValueError: ``path`` exists without the block's two markers (never appended to
            another file: a ``.py`` once got a Markdown table at its end).
    """
    path = Path(path)
    text = path.read_text() if path.is_file() else f"# RL baselines\n\n{BEGIN}\n{END}\n"
    if not (BEGIN in text and END in text):
        raise ValueError(f"--readme {path}: has no results block; put the lines {BEGIN} and "
                         f"{END} where it goes, or give a new file name")
    head, rest = text.split(BEGIN, 1)
    return head, rest.split(END, 1)[1]


def write_readme(path: str | Path, block: str) -> None:
    """Replace the results block of ``path`` (:func:`_readme_parts`)."""
    head, tail = _readme_parts(path)
    atomic_write_text(path, f"{head}{BEGIN}\n{block}{END}{tail}")


def _parsed(env: dict[str, Any]) -> dict[str, Any]:
    """Env arguments compared by meaning (the config JSON parsed, spacing aside)."""
    cfg = env.get("env_config") or "{}"
    try:
        cfg = json.loads(cfg)
    except ValueError:
        pass
    return {**env, "env_config": cfg}


def run(args: Args, command: str) -> str:
    """Evaluate every policy of ``args``; returns the Markdown block (written when
    ``args.readme``)."""
    import torch

    if args.write_readme and not args.readme:
        raise ValueError("--write-readme needs --readme FILE (the block it replaces whole)")
    if args.torch_threads < 1:
        raise ValueError(f"--torch-threads must be >= 1, got {args.torch_threads}")
    if args.episodes < 1 or not 0 <= args.seed <= 2**31 - 1 - args.episodes:
        raise ValueError(f"--episodes must be >= 1 and the seeds --seed .. --seed + --episodes "
                         f"- 1 in [0, 2**31), got --seed {args.seed} --episodes {args.episodes}")
    torch.set_num_threads(args.torch_threads)
    seeds = range(args.seed, args.seed + args.episodes)
    rows: list[tuple[str, dict[str, float], dict[str, Any] | None]] = []
    episodes: list[tuple[str, list[EpisodeResult]]] = []
    output_file(args.csv, "--csv")
    _check_jobs(args)
    for name in args.policies:  # names, then every checkpoint (file, sidecar, weights,
        if name != "random" and name not in DRIVERS:  # temperature): before any episode
            raise ValueError(f"--policies: unknown policy {name!r}; known: {', '.join(POLICIES)}")
    refs: dict[str, tuple[Any, gym.Env]] = {}
    for name in args.policies:  # each driver on this env; the defaults only where they can
        try:
            refs[name] = _reference(name, args)
        except ValueError as exc:
            if args.policies != Args().policies:
                raise
            print(f"note: default policy {name} left out on this env: {exc}")
    if args.write_readme:
        _readme_parts(args.readme)
    ppo = {path: PPOPolicy(path, args.deterministic, args.temperature)
           for path in args.checkpoints}
    _unique_names(list(ppo.values()))
    jobs: list[tuple[Any, Any, bool]] = [(name, None, False) for name in refs]
    jobs += [(None, path, False) for path in args.checkpoints]
    if args.shield:
        check_shield(args.shield)  # before any episode
        # the autopilot drives the world's own controls, not the speed actions
        jobs += [(name, path, True) for name, path, _ in jobs if name != "autopilot"]
    for name, path, shield in jobs:
        if path is None:
            policy, env = refs.pop(name) if name in refs else _reference(name, args)
            meta = None
        else:
            policy = ppo[path]
            env, meta = policy.make_env(args), policy.meta
            trained = {k: meta["args"].get(k) for k in ("env_id", "env_config",
                                                          "max_episode_steps")}
            now = {"env_id": args.env_id, "env_config": args.env_config,
                   "max_episode_steps": args.max_episode_steps}
            if _parsed(trained) != _parsed(now):
                print(f"warning: {path} was trained with --env-id {trained['env_id']} "
                      f"--env-config '{trained['env_config']}' --max-episode-steps "
                      f"{trained['max_episode_steps']}; evaluated with "
                      + " ".join(f"--{k.replace('_', '-')} {v!r}" for k, v in now.items()))
        if shield:
            policy = shielded(policy, args.shield)
        start = time.monotonic()
        try:
            results = evaluate_policy(env, policy, seeds,
                                      log=lambda r: print(policy.name, r, flush=True))
        finally:
            env.close()
        summary = summarize(results)
        print(f"{policy.name}: {len(results)} episodes in {time.monotonic() - start:.0f} s",
              {k: round(v, 3) for k, v in summary.items()}, flush=True)
        rows.append((policy.name, summary, meta))
        episodes.append((policy.name, results))
    block = results_markdown(rows, args, command)
    if args.write_readme:
        write_readme(args.readme, block)
    if args.csv:
        write_results_csv(args.csv, episodes, args)
    return block


def _check_jobs(args: Args) -> None:
    """Refuse, before any episode, an evaluation of nothing (an empty ``$CKPT`` after
    ``--checkpoints`` replaced the CSV with a header), a checkpoint given twice, and a
    ``--shield`` with no policy to hold back."""
    if not args.policies and not args.checkpoints:
        raise ValueError("nothing to evaluate: give --policies NAMES and/or --checkpoints "
                         "FILES")
    check_once(args.checkpoints, "--checkpoints")
    if args.shield and not args.checkpoints and set(args.policies) <= {"autopilot"}:
        raise ValueError("--shield: no policy to hold back (the autopilot drives the world's "
                         "own controls); add --policies or --checkpoints")


def _unique_names(policies: list[PPOPolicy]) -> None:
    """Two checkpoints of one name (``x/s0/model.pt`` and ``y/s0/model.pt``) get their
    paths in the name: the table, the CSV and compare.py tell them apart."""
    names = [p.name for p in policies]
    for p in policies:
        if names.count(p.name) > 1:
            p.name = f"{p.name} [{p.path}]"


def main(argv: list[str] | None = None) -> str:
    """Command-line entry point; returns the Markdown results block."""
    argv = sys.argv[1:] if argv is None else list(argv)
    command = shlex.join(["python", "baselines/evaluate.py", *argv])
    block = run(parse_args(Args, argv), command)
    print(block)
    return block


if __name__ == "__main__":
    cli(main)
