"""PPO (stable-baselines3) driving on DST perception grids, in one readable file.

The agent sees the registered env's default observation: on the RL ids the
``"dict"`` observation ``{"grid": (4, 84, 84) uint8, "ego": speed, acceleration,
steering, target speed, next junction, "route": the route ahead}``
(:mod:`dstenv.envs.navigation`); no wrapper adds anything. Feature extractors
(``--extractor``):

* ``grid-cnn``: :class:`extractors.GridCNN`, three small strided convolutions for the grid
  (84 x 84 -> 6 x 6), concatenated with the flat ``ego`` and ``route`` vectors,
  then one linear layer (cheap on a 2-core CPU);
* ``route-cnn``: :class:`route_features.RouteGridCNN`, ``grid-cnn`` plus a 1-D CNN
  over the grid read along (and across) the observation's route, where a driver
  looks for what is in its way;
* ``combined``: stable-baselines3's own ``MultiInputPolicy`` extractor (NatureCNN on
  the grid), out of the box.

With ``--residual grid`` the policy drives on top of the grid rule driver (:mod:`residual`):
one more action, ``0`` = the rule driver's, and the fresh policy starts as it. With
``--critic privileged`` the critic also reads the nearest road users' ground truth, the
actor the observation only (:mod:`privileged`, an asymmetric actor-critic).

Training runs ``--n-envs`` envs drawing episodes from a pool of maps (``--map-pool``);
``evaluate.py`` runs on fresh maps of held-out seeds. The budget is env steps, not time.

Outputs in ``--out``: ``model.pt`` (the policy's ``state_dict``, loaded back with
``torch.load(weights_only=True)``: no pickled code), ``model.json`` (arguments,
timesteps, wall time, machine), ``progress.csv`` (stable-baselines3's log),
``episodes.csv`` (one row per finished training episode: the learning curve), with
``--tensorboard`` event files. Run::

    python baselines/ppo_grid.py --total-timesteps 200000 --n-envs 2 --out runs/ppo_grid
"""

from __future__ import annotations

import csv
import io
import importlib.util
import json
import shlex
import shutil
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable

import gymnasium as gym
import torch
from gymnasium import spaces
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import configure
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnv, VecNormalize

from dstenv.segment.checkpoint import read_weights

from extractors import GridCNN
from imitation import warm_start, warm_start_steps_per_round
from rl_common import EnvArgs, atomic_write_bytes, atomic_write_text, machine_info, make_env, opt
from rl_common import check_env_args, check_ranges, cli, parse_args, to_argv
from runfolder import claim
from rule_based import TEACHERS

EXTRACTORS = ("grid-cnn", "route-cnn", "combined")


@dataclass
class Args(EnvArgs):
    """Train PPO on a DSTGrid env."""

    extractor: str = opt("grid-cnn", "grid-cnn (small CNN + vectors) | route-cnn (grid-cnn "
                                     "+ the grid read along the route) | combined (SB3's "
                                     "MultiInputPolicy extractor, NatureCNN)")
    features_dim: int = opt(128, "size of the extracted feature vector")
    total_timesteps: int = opt(100_000, "environment steps over all envs (the budget; PPO "
                                        "rounds it up to whole rollouts of n_steps x n_envs)")
    n_envs: int = opt(2, "parallel environments")
    vec_env: str = opt("subproc", "subproc | dummy")
    map_pool: int = opt(50, "training maps (the env's world.map.pool; 0 = a new map "
                            "every episode)")
    seed: int = opt(0, "seed of torch, numpy and the training episodes")
    learning_rate: float = opt(3e-4, "Adam learning rate")
    n_steps: int = opt(256, "rollout steps per env and update")
    batch_size: int = opt(128, "minibatch size")
    n_epochs: int = opt(4, "epochs per update")
    gamma: float = opt(0.99, "discount")
    gae_lambda: float = opt(0.95, "GAE lambda")
    clip_range: float = opt(0.2, "PPO clip range")
    ent_coef: float = opt(0.01, "entropy bonus")
    norm_reward: bool = opt(False, "scale rewards by a running std of the return (SB3 "
                                   "VecNormalize); the logged episodes keep the env's own")
    vf_coef: float = opt(0.5, "value loss weight")
    torch_threads: int = opt(1, "torch CPU threads (envs use the other cores)")
    residual: str = opt("", "'' (none) | grid | grid-tuned: PPO on top of the grid rule "
                            "driver, default or tuned (residual.py): action 0 takes the "
                            "rule driver's action, k >= 1 the env's action k - 1")
    residual_p_rule: float = opt(0.9, "--residual: the fresh policy's P(action 0, the rule)")
    warm_start: str = opt("", "'' (none) | grid | grid-tuned | cautious: DAgger from that driver "
                              "before PPO (imitation.py); its steps count in the budget")
    warm_start_steps: int = opt(24_000, "env steps of the warm start (all rounds and envs)")
    warm_start_rounds: int = opt(4, "DAgger rounds (round 0: the rule driver drives)")
    warm_start_epochs: int = opt(3, "epochs of the supervised fit after each round")
    warm_start_lr: float = opt(3e-4, "Adam rate of the supervised fits (1e-3 before "
                                     "2026-12-06 saturated a six-epoch fit)")
    warm_start_retries: int = opt(2, "refits at a tenth of the rate of a blind DAgger fit")
    critic: str = opt("", "'' (the actor's input) | privileged: an asymmetric critic that "
                          "also reads the nearest road users' ground truth (privileged.py) | "
                          "privileged-vectors: that truth, ego and route, no grid")
    anchor: bool = opt(False, "with --warm-start: PPO's entropy bonus becomes a KL penalty "
                              "to the warm-started policy (anchor.py), --ent-coef its weight")
    checkpoint_every: int = opt(10_000, "save the model every this many steps (before the "
                                        "update of the rollout reaching them); 0: at the end")
    keep_checkpoints: bool = opt(False, "keep every checkpoint as model_<steps>.pt (+ .json) "
                                        "beside model.pt, which each one overwrites; with "
                                        "--warm-start also the policy right after it "
                                        "(model_N.pt = the end of a run of R x (ceil(N / R) "
                                        "- 1) steps, R = n_steps x n_envs)")
    tensorboard: bool = opt(False, "also log to tensorboard (needs the tensorboard extra)")
    out: str = opt("runs/ppo_grid", "output directory")
    verbose: int = opt(1, "0: quiet, 1: stable-baselines3 log table on stdout")


class TrainingLog(BaseCallback):
    """Episode rows to ``episodes.csv`` (the learning curve), checkpoints, wall clock.

    ``timesteps`` of a row counts every env step of the run so far, the warm start's
    (``phase`` ``dagger<round>``) included; PPO's rows (``phase`` ``ppo``) are offset by
    :attr:`offset`, the warm start's steps.
    """

    def __init__(self, args: Args, out: Path) -> None:
        super().__init__()
        self.args, self.out = args, out
        self.start = time.monotonic()
        self.offset = 0
        self.warm: dict[str, Any] | None = None  # the warm start's record for model.json
        self._last_ckpt = 0
        self._fh = open(out / "episodes.csv", "w", newline="")
        self._csv = csv.writer(self._fh)
        self._csv.writerow(["timesteps", "wall_s", "env", "return", "length", "success",
                            "collision", "off_road", "progress_m", "phase"])

    def write_episode(self, timesteps: int, rank: int, ep: dict[str, Any], phase: str) -> None:
        """One row for a finished episode (``Monitor``'s ``info["episode"]``)."""
        self._csv.writerow([timesteps, round(self.elapsed, 1), rank, round(float(ep["r"]), 4),
                            int(ep["l"]), int(ep["is_success"]), int(ep["collision"]),
                            int(ep["off_road"]), round(float(ep["route_progress"]), 2), phase])
        self._fh.flush()

    def _on_step(self) -> bool:
        for rank, info in enumerate(self.locals["infos"]):
            ep = info.get("episode")
            if ep is not None:
                self.write_episode(self.offset + self.num_timesteps, rank, ep, "ppo")
        if 0 < self.args.checkpoint_every <= self.num_timesteps - self._last_ckpt:
            self._last_ckpt = self.num_timesteps  # mid-rollout: before this rollout's update
            self.checkpoint(self.model)
        return True

    def checkpoint(self, model: PPO) -> None:
        """Save ``model.pt`` now; with ``--keep-checkpoints`` also as ``model_<env
        steps>.pt`` (+ ``.json``)."""
        save(model, self.out, self.args, self.elapsed, self.warm)
        if self.args.keep_checkpoints:
            steps = self.offset + model.num_timesteps
            for ext in (".pt", ".json"):
                shutil.copyfile(self.out / f"model{ext}", self.out / f"model_{steps}{ext}")

    @property
    def elapsed(self) -> float:
        return time.monotonic() - self.start

    def _on_training_end(self) -> None:
        self._fh.close()


def train_config(args: Args) -> dict[str, Any]:
    """What training sets on the env under ``--env-config``: the map pool and what the
    ``--warm-start`` teacher needs (``cautious``: ``info.autopilot``, off again for PPO)."""
    return {"world": {"map": {"pool": args.map_pool}}, **TEACHERS.get(args.warm_start, {})}


def env_wrap(residual: str, critic: str) -> Callable[[gym.Env], gym.Env]:
    """The wrappers of a run's env, in training and evaluation alike: ``--residual``
    (:func:`residual.wrap`), then ``--critic`` (:func:`privileged.wrap`)."""
    from privileged import wrap as privileged
    from residual import wrap as residual_wrap

    return lambda env: privileged(residual_wrap(env, residual), critic)


def make_vec_env(args: Args) -> VecEnv:
    """``args.n_envs`` monitored envs in a Dummy/Subproc vector env (seeded at reset)."""
    if args.vec_env not in ("subproc", "dummy"):
        raise ValueError(f"--vec-env: expected subproc or dummy, got {args.vec_env!r}")

    def thunk() -> gym.Env:
        return make_env(args, train_config(args), monitor=True,
                        wrap=env_wrap(args.residual, args.critic))

    cls = SubprocVecEnv if args.vec_env == "subproc" and args.n_envs > 1 else DummyVecEnv
    if cls is SubprocVecEnv:  # a config error in a worker would only say "connection reset"
        thunk().close()
    return cls([thunk] * args.n_envs)


def build_model(args: Args, env: VecEnv | gym.Env) -> PPO:
    """The PPO model for ``args`` on ``env`` (seeded with ``args.seed``)."""
    if args.extractor not in EXTRACTORS:
        raise ValueError(f"--extractor: expected one of {EXTRACTORS}, got {args.extractor!r}")
    dict_obs = isinstance(env.observation_space, spaces.Dict)
    if args.extractor == "grid-cnn":
        policy = "MultiInputPolicy" if dict_obs else "MlpPolicy"
        policy_kwargs: dict[str, Any] = {"features_extractor_class": GridCNN,
                                         "features_extractor_kwargs":
                                             {"features_dim": args.features_dim}}
    elif args.extractor == "route-cnn":
        from route_features import RouteGridCNN

        # the grid and route geometry, from the env's own config
        cfg = env.get_attr("config")[0] if isinstance(env, VecEnv) else env.unwrapped.config
        policy = "MultiInputPolicy"
        policy_kwargs = {"features_extractor_class": RouteGridCNN,
                         "features_extractor_kwargs": {
                             "features_dim": args.features_dim,
                             "cell_size": float(cfg["grid"]["cell_size"]),
                             "route_scale": float(cfg["observation"]["route_points"]
                                                  * cfg["observation"]["route_spacing"])}}
    else:
        policy = "MultiInputPolicy" if dict_obs else "CnnPolicy"
        policy_kwargs = ({"features_extractor_kwargs": {"cnn_output_dim": args.features_dim}}
                         if dict_obs else {"features_extractor_kwargs":
                                           {"features_dim": args.features_dim}})
    if args.critic:
        from privileged import policy_class

        if args.extractor == "combined" or not dict_obs:
            raise ValueError(f"--critic {args.critic}: needs --extractor grid-cnn or route-cnn "
                             "on a dict observation (SB3's own extractor would read the ground "
                             "truth)")
        policy = policy_class(args.critic)  # type: ignore[assignment]
    tb = str(Path(args.out) / "tb") if args.tensorboard else None
    model = PPO(policy, env, learning_rate=args.learning_rate, n_steps=args.n_steps,
               batch_size=args.batch_size, n_epochs=args.n_epochs, gamma=args.gamma,
               gae_lambda=args.gae_lambda, clip_range=args.clip_range, ent_coef=args.ent_coef,
               vf_coef=args.vf_coef, policy_kwargs=policy_kwargs, seed=args.seed,
               device="cpu", verbose=0, tensorboard_log=tb)
    if args.residual:
        from residual import prefer_rule

        prefer_rule(model, args.residual_p_rule)
    return model


def save(model: PPO, out: Path, args: Args, wall_s: float,
         warm: dict[str, Any] | None = None) -> Path:
    """Write ``model.pt`` (the policy's state_dict) and its ``model.json`` sidecar
    atomically; return the ``.pt`` path."""
    buf = io.BytesIO()
    torch.save(model.policy.state_dict(), buf)
    path = out / "model.pt"
    atomic_write_bytes(path, buf.getvalue())
    meta = {
        "args": asdict(args),
        "timesteps": int(model.num_timesteps),  # PPO's env steps
        "env_steps": int(model.num_timesteps) + (warm or {}).get("timesteps", 0),
        "warm_start": warm,
        "wall_time_s": round(wall_s, 1),
        "finished_utc": time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime()),
        "machine": machine_info(),
        "command": shlex.join(["python", "baselines/ppo_grid.py", *to_argv(args)]),
        "observation_space": str(model.observation_space),
        "action_space": str(model.action_space),
    }
    atomic_write_text(out / "model.json", json.dumps(_no_nan(meta), indent=2) + "\n")
    return path


def _no_nan(value: Any) -> Any:
    """NaN (a warm start's statistic of no episode) as null: model.json stays strict JSON."""
    if isinstance(value, float) and value != value:
        return None
    if isinstance(value, dict):
        return {k: _no_nan(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_no_nan(v) for v in value]
    return value


def load(path: str | Path, env: gym.Env, state: Any = None) -> tuple[PPO, dict[str, Any]]:
    """A PPO model rebuilt from ``model.json`` with the weights of ``model.pt``.

    Only tensors are read (``torch.load(weights_only=True)``): a checkpoint cannot
    run code. ``env`` gives the spaces (it must match those of training); ``state``:
    the weights when already read (:func:`read_weights`).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such checkpoint")
    sidecar = path.with_suffix(".json")
    if not sidecar.is_file():
        raise FileNotFoundError(f"{path}: missing its sidecar {sidecar.name}")
    meta = json.loads(sidecar.read_text())
    spaces_now = (str(env.observation_space), str(env.action_space))
    trained = (meta.get("observation_space", spaces_now[0]), meta.get("action_space",
                                                                      spaces_now[1]))
    if spaces_now != trained:
        raise ValueError(f"{path}: trained on {meta['observation_space']} / "
                         f"{meta['action_space']}, the env gives {spaces_now[0]} / "
                         f"{spaces_now[1]} (grid size, observation or action type?)")
    known = {f for f in Args.__dataclass_fields__}
    args = Args(**{k: v for k, v in meta["args"].items() if k in known})
    model = build_model(args, env)
    state = read_weights(path, "not a readable policy checkpoint") if state is None else state
    if not isinstance(state, dict):
        raise ValueError(f"{path}: not a policy checkpoint (a state_dict of tensors)")
    try:
        model.policy.load_state_dict(state)
    except RuntimeError as exc:
        raise ValueError(f"{path}: its weights do not fit the network {sidecar.name} describes "
                         f"(extractor {args.extractor}; {str(exc).splitlines()[0]}); keep the "
                         "pair ppo_grid.py wrote") from None
    return model, meta


def train(args: Args) -> tuple[PPO, dict[str, Any]]:
    """Train PPO as ``args`` says; returns the model and the ``model.json`` content."""
    a, lows = args, {"total_timesteps": 1, "n_envs": 1, "n_steps": 2, "batch_size": 2,
                     "n_epochs": 1, "torch_threads": 1, "features_dim": 1, "checkpoint_every": 0,
                     "warm_start_retries": 0, "warm_start_epochs": 1, "clip_range": 1e-6,
                     "ent_coef": 0.0, "vf_coef": 0.0}
    check_ranges([(f"--{k.replace('_', '-')}", getattr(a, k), lo) for k, lo in lows.items()]
                 + [("--gamma", a.gamma, 0.0, 1.0), ("--gae-lambda", a.gae_lambda, 0.0, 1.0)])
    check_env_args(args)
    if args.residual and args.warm_start:
        raise ValueError("--residual with --warm-start: the residual policy starts as the "
                         "rule driver already; use one of the two")
    if args.warm_start:
        if args.norm_reward:
            raise ValueError("--norm-reward with --warm-start: the warm start fits the value "
                             "head to the env's own returns; use one of the two")
        warm_start_steps_per_round(args)  # bad flags fail before any env is built
    if args.anchor and not args.warm_start:
        raise ValueError("--anchor needs --warm-start (the imitation policy it stays near)")
    if args.anchor and args.ent_coef <= 0:
        raise ValueError(f"--anchor needs --ent-coef > 0 (the KL's weight), got "
                         f"{args.ent_coef}")
    if args.tensorboard and importlib.util.find_spec("tensorboard") is None:
        raise ValueError("--tensorboard needs the tensorboard package: pip install -e "
                         "'.[tensorboard]'")
    with claim(args.out) as out:  # one run per folder, held while it trains
        return _train(args, out)


def _train(args: Args, out: Path) -> tuple[PPO, dict[str, Any]]:
    torch.set_num_threads(args.torch_threads)
    env = make_vec_env(args)
    if args.norm_reward:
        env = VecNormalize(env, norm_obs=False, norm_reward=True, gamma=args.gamma)
    try:
        model = build_model(args, env)
        formats = ["stdout", "csv"] if args.verbose else ["csv"]
        model.set_logger(configure(str(out), formats + (["tensorboard"] if args.tensorboard
                                                        else [])))
        log = TrainingLog(args, out)
        ppo_steps = args.total_timesteps
        if args.warm_start:
            log.warm = warm_start(
                args, model, env, lambda r, i, steps, ep: log.write_episode(steps, i, ep,
                                                                            f"dagger{r}"),
                lambda: make_env(args, train_config(args), wrap=env_wrap(args.residual,
                                                                         args.critic)))
            log.offset = log.warm["timesteps"]
            ppo_steps -= log.offset
            log.checkpoint(model)  # the imitation policy alone, before PPO
            if args.anchor:
                from anchor import anchor_to

                anchor_to(model.policy)
        model.learn(total_timesteps=max(ppo_steps, 0), callback=log, progress_bar=False)
        save(model, out, args, log.elapsed, log.warm)
    finally:
        env.close()
    meta = json.loads((out / "model.json").read_text())
    n, wall = meta.get("env_steps", meta["timesteps"]), meta["wall_time_s"]  # warm start too
    print(f"saved {out / 'model.pt'}: {n} env steps in {wall} s ({n / max(wall, 1e-9):.1f}/s)")
    return model, meta


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Command-line entry point; returns the ``model.json`` content."""
    return train(parse_args(Args, argv))[1]


if __name__ == "__main__":
    cli(main)
