"""Warm start for PPO: imitate the grid rule driver (DAgger) before reinforcement learning.

PPO from scratch on ``DSTGrid-Occluded-v0`` plateaus at ~50 % training success: a
random initial policy rarely drives carefully through an occluded junction, so the
reward for doing so is seldom seen. The grid rule driver (:mod:`rule_based`) sees
only the observation the policy sees, so it can label *any* observation with its
action. DAgger (Ross, Gordon & Bagnell, AISTATS 2011) uses that:

1. round 0: the rule driver drives; its observations and actions are kept;
2. round ``r >= 1``: the current policy drives (sampling its actions); the rule
   driver labels every observation it meets, so the data covers the states the
   learner's own mistakes lead to (each step the rule driver still acts with
   probability ``0.5 ** r``, the usual decaying mixture);
3. after each round the policy's action head is fitted to all labels so far
   (cross-entropy, each class weighted by its inverse frequency, at most 10x: the rule
   driver holds its target speed in ~93 % of steps, and the rare SLOWER before an
   obstacle is what matters), then its value head to the discounted returns of the episodes
   (features frozen; a critic with its own extractor, ``--critic privileged``, fits
   that too), so that PPO starts with a value baseline of the same policy;
4. a fit after which the policy answers every observation alike (its logits' spread
   below :data:`DEAD_SPREAD`: at too high a rate the features grow until the policy
   MLP's tanh layer saturates) is undone and redone at a tenth of the rate, which the
   later rounds keep (at most ``retries`` times).

PPO then continues from this policy with its own reward. Every env step of the
warm start counts in the training budget: :func:`dagger` returns their number and
``ppo_grid.py`` adds it to the step axis of ``episodes.csv``.
"""

from __future__ import annotations

import copy
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import VecEnv
from torch import nn

__all__ = ["DEAD_SPREAD", "DaggerLog", "dagger", "discounted_returns", "warm_start",
           "warm_start_steps_per_round"]

#: a fit whose held-out logits vary less than this across observations has a policy
#: that ignores its input (logged as such; a fresh policy's spread is ~1e-3, a trained one's ~1)
DEAD_SPREAD = 1e-5


@dataclass
class DaggerLog:
    """What the warm start did: env steps, wall time and per-round statistics."""

    timesteps: int = 0
    wall_s: float = 0.0
    rounds: list[dict[str, float]] = field(default_factory=list)


def discounted_returns(rewards: np.ndarray, dones: np.ndarray, gamma: float) -> np.ndarray:
    """Discounted return of every step of ``(T, N)`` rewards of ``N`` envs.

    ``dones[t, i]`` ends env ``i``'s episode after step ``t``; episodes still running
    at ``T`` are cut there (no bootstrap). Returns ``(T, N)`` float32.
    """
    out = np.zeros(rewards.shape, np.float32)
    g = np.zeros(rewards.shape[1], np.float64)
    for t in range(len(rewards) - 1, -1, -1):
        g = rewards[t] + gamma * g * (1.0 - dones[t])
        out[t] = g
    return out


def _rollout(venv: VecEnv, model: PPO, expert: Any, steps: int, beta: float,
             rng: np.random.Generator, on_episode: Callable[[int, int, dict[str, Any]], None]
             ) -> dict[str, np.ndarray]:
    """``steps`` vector steps driven by the expert (each env step with probability
    ``beta``, else by the learner, sampling its actions); every observation
    labelled with the expert's action; ``on_episode(env index, env steps so far,
    info["episode"])`` for each episode that ends. Returns stacked observations, labels, rewards."""
    obs = venv.reset()
    keys = sorted(obs)
    buf: dict[str, list[np.ndarray]] = {k: [] for k in keys}
    labels, rewards, dones = [], [], []
    n = venv.num_envs
    infos = list(venv.reset_infos)  # the info of each env's current observation
    for t in range(steps):
        label = np.array([expert.act({k: obs[k][i] for k in keys}, infos[i])
                          for i in range(n)])
        for k in keys:
            buf[k].append(obs[k].copy())
        labels.append(label)
        action = label
        if beta < 1.0:
            own = model.policy.predict(obs, deterministic=False)[0]
            action = np.where(rng.random(n) < beta, label, own)
        obs, reward, done, infos = venv.step(action)
        rewards.append(reward)
        dones.append(done)
        for i, info in enumerate(infos):
            if "episode" in info:
                on_episode(i, (t + 1) * n, info["episode"])
        # a finished episode's env was reset: its observation is the new episode's
        infos = [venv.reset_infos[i] if done[i] else infos[i] for i in range(n)]
    out = {k: np.concatenate(v) for k, v in buf.items()}  # step-major: row t * n + i
    out["label"] = np.concatenate(labels)
    out["rewards"] = np.stack(rewards).astype(np.float64)
    out["dones"] = np.stack(dones).astype(np.float64)
    return out


def _batches(n: int, size: int, rng: np.random.Generator) -> list[np.ndarray]:
    order = rng.permutation(n)
    return [order[i:i + size] for i in range(0, n, size)]


def _fit(model: PPO, data: dict[str, np.ndarray], returns: np.ndarray, epochs: int,
         lr: float, batch: int, rng: np.random.Generator) -> dict[str, float]:
    """Fit the action head to the labels, then the value head to ``returns``; returns
    the held-out (last 10 %) label accuracy, its class-balanced twin (mean recall over
    the classes present), the value error and ``logit_spread``, the logits' standard
    deviation over the held-out observations (mean over actions): ~0 when the policy
    answers every observation alike, as when the features grew until the policy MLP's
    first tanh layer saturated (a fit at too high a rate; see :data:`DEAD_SPREAD`)."""
    policy = model.policy
    keys = [k for k in data if k != "label"]
    n = len(data["label"])
    n_val = max(n // 10, 1)
    train_idx, val_idx = np.arange(n - n_val), np.arange(n - n_val, n)

    def obs(idx: np.ndarray) -> Any:
        return policy.obs_to_tensor({k: data[k][idx] for k in keys})[0]

    # a critic with its own extractor (--critic privileged) fits it with the value head
    own = not policy.share_features_extractor
    value_params = [*policy.mlp_extractor.value_net.parameters(),
                    *policy.value_net.parameters(),
                    *(policy.vf_features_extractor.parameters() if own else ())]
    ids = {id(p) for p in value_params}
    actor_params = [p for p in policy.parameters() if id(p) not in ids]
    counts = np.bincount(data["label"][train_idx], minlength=int(model.action_space.n))
    weight = np.minimum(counts.max() / np.maximum(counts, 1), 10.0)
    ce = nn.CrossEntropyLoss(weight=torch.as_tensor(weight, dtype=torch.float32))
    mse = nn.MSELoss()
    policy.set_training_mode(True)
    opt = torch.optim.Adam(actor_params, lr=lr)
    for _ in range(epochs):
        for idx in _batches(len(train_idx), batch, rng):
            logits = policy.get_distribution(obs(train_idx[idx])).distribution.logits
            loss = ce(logits, torch.as_tensor(data["label"][train_idx[idx]]).long())
            opt.zero_grad()
            loss.backward()
            opt.step()
    opt = torch.optim.Adam(value_params, lr=lr)
    target = torch.as_tensor(returns, dtype=torch.float32)
    for _ in range(epochs):
        for idx in _batches(len(train_idx), batch, rng):
            o = obs(train_idx[idx])
            if own:  # the critic's extractor alone, with gradients
                v = policy.predict_values(o).flatten()
            else:
                with torch.no_grad():
                    latent = policy.extract_features(o)
                v = policy.value_net(policy.mlp_extractor.forward_critic(latent)).flatten()
            loss = mse(v, target[train_idx[idx]])
            opt.zero_grad()
            loss.backward()
            opt.step()
    policy.set_training_mode(False)
    with torch.no_grad():
        o = obs(val_idx)
        logits = policy.get_distribution(o).distribution.logits
        pred = logits.argmax(1).numpy()
        v = policy.predict_values(o).flatten().numpy()
    truth = data["label"][val_idx]
    recall = [float((pred[truth == c] == c).mean()) for c in np.unique(truth)]
    return {"accuracy": float((pred == truth).mean()), "balanced_accuracy": float(np.mean(recall)),
            "value_rmse": float(np.sqrt(np.mean((v - returns[val_idx]) ** 2))),
            "logit_spread": float(logits.std(0).mean()) if len(val_idx) > 1 else float("nan")}


def dagger(model: PPO, venv: VecEnv, expert: Any, rounds: int, steps_per_round: int,
           epochs: int = 3, lr: float = 3e-4, batch: int = 256, seed: int = 0,
           retries: int = 2,
           on_episode: Callable[[int, int, int, dict[str, Any]], None] | None = None,
           log: Callable[[str], None] = print) -> DaggerLog:
    """Warm-start ``model``'s policy by DAgger from ``expert`` (see the module docstring).

    Args:
        model: the PPO model whose policy is trained in place.
        venv: its vector env (the training env; reset at every round).
        expert: a driver with ``act(obs, info) -> int`` on single observations and the
            ``info`` of each (the :class:`rule_based.GridRuleDriver` or
            :class:`rule_based.CautiousDriver`, already ``reset`` on an env of the same
            config).
        rounds: DAgger rounds (round 0 is the expert's own driving).
        steps_per_round: vector steps per round (``venv.num_envs`` env steps each).
        epochs, lr, batch: the supervised fit after each round (Adam; the rate is
            ``ppo_grid.py --warm-start-lr``'s default, 3e-4).
        retries: refits of a round whose fitted policy ignores its input, each from the
            weights before that fit at a tenth of the rate (kept for later rounds).
        seed: seed of the minibatch order.
        on_episode: called with ``(round, env index, env steps so far,
            info["episode"])`` for every
            episode that ends (``Monitor`` statistics).
        log: one line per round.

    Returns:
        :class:`DaggerLog` (env steps used, wall time, per-round accuracy and
        episode success of the round's driver).
    """
    rng = np.random.default_rng(seed)
    start = time.monotonic()
    result = DaggerLog()
    data: dict[str, np.ndarray] = {}
    returns = np.zeros(0, np.float32)
    for r in range(rounds):
        ended: list[dict[str, Any]] = []

        def record(i: int, steps: int, ep: dict[str, Any], r: int = r,
                   ended: list = ended) -> None:
            ended.append(ep)
            if on_episode is not None:
                on_episode(r, i, result.timesteps + steps, ep)

        part = _rollout(venv, model, expert, steps_per_round, 0.5 ** r, rng, record)
        result.timesteps += steps_per_round * venv.num_envs
        part_returns = discounted_returns(part.pop("rewards"), part.pop("dones"),
                                          model.gamma).reshape(-1)
        data = {k: np.concatenate([data[k], v]) if data else v for k, v in part.items()}
        returns = np.concatenate([returns, part_returns])
        before = copy.deepcopy(model.policy.state_dict())
        stats = _fit(model, data, returns, epochs, lr, batch, rng)
        refits = 0
        while stats["logit_spread"] < DEAD_SPREAD and refits < retries:
            log(f"dagger round {r}: the fitted policy ignores its input (logit spread "
                f"{stats['logit_spread']:.1e} at rate {lr:g}): refitting at {lr / 10:g}")
            model.policy.load_state_dict(before)
            lr, refits = lr / 10, refits + 1
            stats = _fit(model, data, returns, epochs, lr, batch, rng)
        success = float(np.mean([ep["is_success"] for ep in ended])) if ended else float("nan")
        collision = float(np.mean([ep["collision"] for ep in ended])) if ended else float("nan")
        row = {"round": r, "expert_share": 0.5 ** r, "samples": len(returns),
               "episodes": len(ended), "success": success, "collision": collision, **stats,
               "fit_lr": lr, "refits": refits,
               "wall_s": round(time.monotonic() - start, 1)}
        result.rounds.append(row)
        log(f"dagger round {r} (rule driver's share {0.5 ** r:.2f}): {len(ended)} episodes, "
            f"success {success:.2f}, collision {collision:.2f}; {len(returns)} labels, "
            f"held-out accuracy {stats['accuracy']:.3f} (balanced "
            f"{stats['balanced_accuracy']:.3f}), value rmse {stats['value_rmse']:.2f}"
            + ("; the policy ignores its input (logit spread "
               f"{stats['logit_spread']:.1e}): lower --warm-start-lr"
               if stats["logit_spread"] < DEAD_SPREAD else ""))
    result.wall_s = time.monotonic() - start
    return result


def warm_start_steps_per_round(args: Any) -> int:
    """Vector steps per DAgger round of ``ppo_grid.py``'s warm start (``args``: its
    ``Args``).

    Raises:
        ValueError: an unknown ``--warm-start``, ``--warm-start-steps`` below one step
            per round and env or not below ``--total-timesteps``, or a
            ``--warm-start-lr`` that is not positive.
    """
    from rule_based import TEACHERS

    if args.warm_start not in TEACHERS:
        raise ValueError(f"--warm-start: expected '' or one of {', '.join(TEACHERS)}, got "
                         f"{args.warm_start!r}")
    if not args.warm_start_lr > 0:
        raise ValueError(f"--warm-start-lr {args.warm_start_lr}: must be positive")
    rounds = args.warm_start_rounds
    per_round = args.warm_start_steps // (rounds * args.n_envs) if rounds > 0 else 0
    if per_round < 1 or args.warm_start_steps >= args.total_timesteps:
        raise ValueError(f"--warm-start-steps {args.warm_start_steps}: needs >= one step per "
                         f"round and env ({rounds} x {args.n_envs}) and less than "
                         f"--total-timesteps {args.total_timesteps}")
    return per_round


def warm_start(args: Any, model: PPO, venv: VecEnv, on_episode: Callable[..., None],
               probe: Callable[[], Any]) -> dict[str, Any]:
    """DAgger from the teacher ``args.warm_start`` of :data:`rule_based.TEACHERS` on
    ``ppo_grid.py``'s training env ``venv``; returns its record for ``model.json`` (env
    steps, wall time, rounds).

    Args:
        on_episode: ``(round, env index, env steps so far, info["episode"])`` of each
            episode that ends.
        probe: builds one env of the training config, on which the teacher is reset.
    """
    from rule_based import TEACHERS, teacher

    per_round = warm_start_steps_per_round(args)
    expert, method = teacher(args.warm_start)
    env = probe()
    try:
        env.reset(seed=args.seed)
        expert.reset(env, args.seed)
    finally:
        env.close()
    result = dagger(model, venv, expert, args.warm_start_rounds, per_round,
                    epochs=args.warm_start_epochs, lr=args.warm_start_lr, seed=args.seed,
                    retries=args.warm_start_retries, on_episode=on_episode,
                    log=print if args.verbose else (lambda _: None))
    if TEACHERS[args.warm_start]:  # the teacher's env settings (info.autopilot) are not PPO's
        venv.env_method("reset", options={"config": {"info": {"autopilot": False}}})
    return {"method": method, "timesteps": result.timesteps,
            "wall_s": round(result.wall_s, 1), "rounds": result.rounds}


if __name__ == "__main__":
    raise SystemExit(f"{__file__}: a part of ppo_grid.py, not a script of its own; run "
                     "python baselines/ppo_grid.py --warm-start ... (baselines/README.md)")
