"""Keep PPO near its warm start: a KL penalty to the imitation policy in place of the
entropy bonus.

After DAgger (:mod:`imitation`) the policy drives about as well as its teacher; PPO
with its own reward then drifts, and on the validation seeds that drift made it worse
(``baselines/README.md``). The usual fix in fine-tuning a pretrained policy (e.g. the
KL to the pretrained model in Baker et al., "Video PreTraining", NeurIPS 2022) is a
penalty on the divergence from it. Here it replaces PPO's entropy bonus, of which it
is the generalisation: with ``H`` the entropy and ``U`` the uniform policy,
``-H(pi) = KL(pi || U) - log |A|``, so the bonus pulls the policy towards uniform;
with the anchor ``pi_0`` the same term pulls it towards ``pi_0``::

    loss = policy_loss + ent_coef * mean(KL(pi(.|s) || pi_0(.|s))) + vf_coef * value_loss

:func:`anchor_to` makes stable-baselines3's PPO do exactly this without copying its
training loop: PPO adds ``-ent_coef * mean(entropy)`` from the policy's
``evaluate_actions``, and the anchored policy reports ``-KL`` as that entropy (so
``train/entropy_loss`` in ``progress.csv`` logs the mean KL). The KL reuses the action
distribution that ``evaluate_actions`` builds (no second forward pass of the policy);
only the frozen anchor runs once more, without gradients.
"""

from __future__ import annotations

import copy
from typing import Callable

import torch
from stable_baselines3.common.distributions import Distribution
from stable_baselines3.common.policies import ActorCriticPolicy
from torch.distributions import kl_divergence

__all__ = ["anchor_to", "kl_to_anchor"]


def _kl(dist: Distribution, anchor: ActorCriticPolicy,
        obs: torch.Tensor | dict[str, torch.Tensor]) -> torch.Tensor:
    """``KL(dist || anchor(.|obs))``, ``(B,)``; the anchor runs without gradients."""
    with torch.no_grad():
        target = anchor.get_distribution(obs).distribution
    return kl_divergence(dist.distribution, target)


def kl_to_anchor(policy: ActorCriticPolicy, anchor: ActorCriticPolicy,
                 obs: torch.Tensor | dict[str, torch.Tensor]) -> torch.Tensor:
    """``KL(policy(.|s) || anchor(.|s))`` per observation, ``(B,)``; differentiable in
    ``policy`` only (the anchor is evaluated without gradients)."""
    return _kl(policy.get_distribution(obs), anchor, obs)


def anchor_to(policy: ActorCriticPolicy) -> ActorCriticPolicy:
    """Freeze a copy of ``policy`` as its anchor and make its ``evaluate_actions``
    report ``-KL(policy || anchor)`` as the entropy (see the module docstring).

    The anchor is held outside the policy's modules: ``policy.state_dict()`` (the
    checkpoint) is unchanged. Returns the frozen anchor.
    """
    anchor = copy.deepcopy(policy)
    anchor.set_training_mode(False)
    for p in anchor.parameters():
        p.requires_grad_(False)
    evaluate: Callable = policy.evaluate_actions
    to_dist: Callable = policy._get_action_dist_from_latent
    last: list = []  # the distribution evaluate_actions built: no second forward pass

    def keep_dist(latent_pi):  # type: ignore[no-untyped-def]
        last[:] = [to_dist(latent_pi)]
        return last[0]

    def evaluate_actions(obs, actions):  # type: ignore[no-untyped-def]
        last.clear()
        values, log_prob, _ = evaluate(obs, actions)
        if len(last) != 1:  # a stable-baselines3 that builds it another way
            raise RuntimeError("anchor_to: evaluate_actions did not build one action "
                               "distribution through _get_action_dist_from_latent")
        return values, log_prob, -_kl(last[0], anchor, obs)

    policy._get_action_dist_from_latent = keep_dist  # type: ignore[method-assign]
    policy.evaluate_actions = evaluate_actions  # type: ignore[method-assign]
    return anchor


if __name__ == "__main__":
    raise SystemExit(f"{__file__}: a part of ppo_grid.py, not a script of its own; run "
                     "python baselines/ppo_grid.py --anchor ... (baselines/README.md)")
