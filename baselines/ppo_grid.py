"""PPO (stable-baselines3) driving on DST perception grids, in one readable file.

The agent sees the env's grid observation (``--obs``: ``pignistic`` 5 x H x W,
``fcn10`` 10 x H x W, ``masses`` 32 x H x W floats, or the ``image`` uint8 mode)
plus, by default, an ego vector (``--ego-state speed+route``: its speed and the
route 5..40 m ahead, :class:`rl_common.EgoStateObservation`; one ego-centred grid
shows neither). Feature extractors (``--extractor``):

* ``grid-cnn``: :class:`GridCNN`, four small strided convolutions for float grids
  of a few channels (84 x 84 -> 6 x 6), then one linear layer;
* ``nature-cnn``: stable-baselines3's ``CnnPolicy`` (NatureCNN) on ``--obs image``
  (``MultiInputPolicy`` with the ego vector).

Outputs in ``--out``: ``model.zip`` (written atomically, also every
``--checkpoint-every`` steps), ``model.json`` (arguments, timesteps done, wall time,
machine), ``progress.csv`` (stable-baselines3's training log) and ``episodes.csv``
(one row per finished training episode). Run::

    python baselines/ppo_grid.py --total-timesteps 200000 --n-envs 2 --out runs/ppo_grid
"""

from __future__ import annotations

import csv
import io
import json
import shlex
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import configure
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnv
from torch import nn

from rl_common import EnvArgs, atomic_write_bytes, atomic_write_text, machine_info, make_env, opt
from rl_common import parse_args, to_argv

EXTRACTORS = ("grid-cnn", "nature-cnn")


@dataclass
class Args(EnvArgs):
    """Train PPO on a DSTGrid env."""

    obs: str = opt("pignistic", "observation type: pignistic | fcn10 | masses | image")
    extractor: str = opt("grid-cnn", "grid-cnn (custom, float grids) | nature-cnn (SB3 "
                                     "CnnPolicy, needs --obs image)")
    ego_state: str = opt("speed+route", "ego vector beside the grid: none | speed | "
                                        "speed+route (the route 5..40 m ahead)")
    features_dim: int = opt(256, "size of the extracted feature vector")
    total_timesteps: int = opt(100_000, "environment steps over all envs")
    max_wall_time: float = opt(0.0, "[s] stop training (and save) after this; 0 = no limit")
    n_envs: int = opt(2, "parallel environments")
    vec_env: str = opt("subproc", "subproc | dummy")
    seed: int = opt(0, "seed of torch, numpy and the training episodes")
    learning_rate: float = opt(3e-4, "Adam learning rate")
    n_steps: int = opt(256, "rollout steps per env and update")
    batch_size: int = opt(128, "minibatch size")
    n_epochs: int = opt(4, "epochs per update")
    gamma: float = opt(0.99, "discount")
    gae_lambda: float = opt(0.95, "GAE lambda")
    clip_range: float = opt(0.2, "PPO clip range")
    ent_coef: float = opt(0.01, "entropy bonus")
    vf_coef: float = opt(0.5, "value loss weight")
    torch_threads: int = opt(1, "torch CPU threads (envs use the other cores)")
    checkpoint_every: int = opt(0, "save the model every this many steps; 0 = at the end only")
    record_actions: int = opt(64, "keep the first this many training actions (env 0)")
    out: str = opt("runs/ppo_grid", "output directory")
    verbose: int = opt(1, "0: quiet, 1: stable-baselines3 log table on stdout")


class GridCNN(BaseFeaturesExtractor):
    """A small CNN for ``(C, H, W)`` perception grids, optionally with extra vectors.

    A 4x4 convolution of stride 4 first cuts the grid into 4 x 4-cell patches
    (84 -> 21; cheap enough for a 2-core CPU), two 3x3 convolutions of stride 2
    follow (21 -> 11 -> 6, a cell of the last map sees ~28 cells), and a linear
    layer maps them to ``features_dim``. Float grids in [0, 1] (BetP, masses) enter
    as they are; uint8 grids are scaled to [0, 1] by stable-baselines3 first.

    Args:
        observation_space: a ``Box`` ``(C, H, W)``, or a ``Dict`` with key ``"grid"``
            (that ``Box``) and flat ``Box`` vectors (e.g. ``"ego"``) concatenated
            after the convolutions.
        features_dim: output size.
    """

    def __init__(self, observation_space: spaces.Space, features_dim: int = 256) -> None:
        super().__init__(observation_space, features_dim)
        if isinstance(observation_space, spaces.Dict):
            grid = observation_space["grid"]
            self.vector_keys = sorted(k for k in observation_space.spaces if k != "grid")
            n_vec = sum(int(np.prod(observation_space[k].shape)) for k in self.vector_keys)
        else:
            grid, self.vector_keys, n_vec = observation_space, [], 0
        if len(grid.shape) != 3 or min(grid.shape[1:]) < 16:
            raise ValueError(f"GridCNN: grid observation must be (C, H, W) with H, W >= 16, "
                             f"got {grid.shape}")
        c = grid.shape[0]
        self.cnn = nn.Sequential(
            nn.Conv2d(c, 32, 4, stride=4), nn.ReLU(),
            nn.Conv2d(32, 64, 3, stride=2, padding=1), nn.ReLU(),
            nn.Conv2d(64, 64, 3, stride=2, padding=1), nn.ReLU(),
            nn.Flatten(),
        )
        with torch.no_grad():
            n_flat = self.cnn(torch.zeros(1, *grid.shape)).shape[1]
        self.head = nn.Sequential(nn.Linear(n_flat + n_vec, features_dim), nn.ReLU())

    def forward(self, observations: Any) -> torch.Tensor:
        if not self.vector_keys:
            return self.head(self.cnn(observations))
        parts = [self.cnn(observations["grid"])]
        parts += [observations[k].flatten(1) for k in self.vector_keys]
        return self.head(torch.cat(parts, dim=1))


class TrainingLog(BaseCallback):
    """Episode rows to ``episodes.csv``, the first actions, checkpoints and the wall clock."""

    def __init__(self, args: Args, out: Path) -> None:
        super().__init__()
        self.args, self.out = args, out
        self.first_actions: list[int | list[float]] = []
        self.start = time.monotonic()
        self._last_ckpt = 0
        self._fh = open(out / "episodes.csv", "w", newline="")
        self._csv = csv.writer(self._fh)
        self._csv.writerow(["timesteps", "wall_s", "env", "return", "length", "collision",
                            "off_road", "progress_m"])

    def _on_step(self) -> bool:
        if len(self.first_actions) < self.args.record_actions:
            self.first_actions.append(np.asarray(self.locals["actions"][0]).tolist())
        for rank, info in enumerate(self.locals["infos"]):
            ep = info.get("episode")
            if ep is not None:
                self._csv.writerow([self.num_timesteps, round(self.elapsed, 1), rank,
                                    round(float(ep["r"]), 4), int(ep["l"]), int(ep["collision"]),
                                    int(ep["off_road"]), round(float(ep["route_progress"]), 2)])
                self._fh.flush()
        every = self.args.checkpoint_every
        if every > 0 and self.num_timesteps - self._last_ckpt >= every:
            self._last_ckpt = self.num_timesteps
            save(self.model, self.out, self.args, self.elapsed, self.first_actions)
        limit = self.args.max_wall_time
        return not (limit > 0 and self.elapsed >= limit)

    @property
    def elapsed(self) -> float:
        return time.monotonic() - self.start

    def _on_training_end(self) -> None:
        self._fh.close()


def make_vec_env(args: Args) -> VecEnv:
    """``args.n_envs`` monitored envs in a Dummy/Subproc vector env (seeded at reset)."""
    if args.vec_env not in ("subproc", "dummy"):
        raise ValueError(f"--vec-env: expected subproc or dummy, got {args.vec_env!r}")

    def thunk() -> gym.Env:
        return make_env(args, args.obs, args.ego_state, monitor=True)

    cls = SubprocVecEnv if args.vec_env == "subproc" and args.n_envs > 1 else DummyVecEnv
    return cls([thunk] * args.n_envs)


def build_model(args: Args, env: VecEnv) -> PPO:
    """The PPO model for ``args`` on ``env`` (seeded with ``args.seed``)."""
    if args.extractor not in EXTRACTORS:
        raise ValueError(f"--extractor: expected one of {EXTRACTORS}, got {args.extractor!r}")
    dict_obs = isinstance(env.observation_space, spaces.Dict)
    if args.extractor == "grid-cnn":
        policy = "MultiInputPolicy" if dict_obs else "MlpPolicy"
        policy_kwargs: dict[str, Any] = {"features_extractor_class": GridCNN,
                                         "features_extractor_kwargs":
                                             {"features_dim": args.features_dim}}
    else:
        if args.obs != "image":
            raise ValueError("--extractor nature-cnn needs --obs image (uint8 grids)")
        policy = "MultiInputPolicy" if dict_obs else "CnnPolicy"
        policy_kwargs = ({"features_extractor_kwargs": {"cnn_output_dim": args.features_dim}}
                         if dict_obs else {"features_extractor_kwargs":
                                           {"features_dim": args.features_dim}})
    return PPO(policy, env, learning_rate=args.learning_rate, n_steps=args.n_steps,
               batch_size=args.batch_size, n_epochs=args.n_epochs, gamma=args.gamma,
               gae_lambda=args.gae_lambda, clip_range=args.clip_range, ent_coef=args.ent_coef,
               vf_coef=args.vf_coef, policy_kwargs=policy_kwargs, seed=args.seed,
               device="cpu", verbose=0)


def save(model: PPO, out: Path, args: Args, wall_s: float,
         first_actions: list[Any] | None = None) -> Path:
    """Write ``model.zip`` and its ``model.json`` sidecar atomically; return the zip path."""
    buf = io.BytesIO()
    model.save(buf)
    path = out / "model.zip"
    atomic_write_bytes(path, buf.getvalue())
    meta = {
        "args": asdict(args),
        "timesteps": int(model.num_timesteps),
        "wall_time_s": round(wall_s, 1),
        "finished_utc": time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime()),
        "machine": machine_info(),
        "command": shlex.join(["python", "baselines/ppo_grid.py", *to_argv(args)]),
        "first_actions": first_actions or [],
    }
    atomic_write_text(out / "model.json", json.dumps(meta, indent=2) + "\n")
    return path


def train(args: Args) -> tuple[PPO, dict[str, Any]]:
    """Train PPO as ``args`` says; returns the model and the ``model.json`` content."""
    torch.set_num_threads(args.torch_threads)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    env = make_vec_env(args)
    try:
        model = build_model(args, env)
        formats = ["stdout", "csv"] if args.verbose else ["csv"]
        model.set_logger(configure(str(out), formats))
        log = TrainingLog(args, out)
        model.learn(total_timesteps=args.total_timesteps, callback=log, progress_bar=False)
        save(model, out, args, log.elapsed, log.first_actions)
    finally:
        env.close()
    meta = json.loads((out / "model.json").read_text())
    print(f"saved {out / 'model.zip'}: {meta['timesteps']} steps in {meta['wall_time_s']} s "
          f"({meta['timesteps'] / max(meta['wall_time_s'], 1e-9):.1f} steps/s)")
    return model, meta


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Command-line entry point; returns the ``model.json`` content."""
    return train(parse_args(Args, argv))[1]


if __name__ == "__main__":
    main(sys.argv[1:])
