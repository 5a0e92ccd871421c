"""PPO on top of the grid rule driver: a residual policy that learns when to override.

Residual policy learning (Silver et al., 2018; Johannink et al., 2019) starts a
learner from a hand-written controller and lets it learn corrections. Here the
controller is :class:`rule_based.GridRuleDriver`, which sees only the observation,
so the combined driver is still a perception-grid driver (nothing privileged).

:class:`RuleResidual` turns an env with ``n`` actions (SLOWER, IDLE, FASTER, ...)
into one with ``n + 1``: action ``0`` (``RULE``) takes the rule driver's action for
the current observation, action ``k >= 1`` takes the env's action ``k - 1``. The
observation, rewards and ``info`` are the env's (``info["override"]`` says whether
the policy overrode the rule driver). :func:`prefer_rule` biases a fresh PPO
policy's ``RULE`` logit so that it starts as the rule driver (its most likely
action is ``RULE`` everywhere) and explores overrides with a set probability.

Used by ``ppo_grid.py --residual grid``; ``evaluate.py`` rebuilds the wrapper from
the checkpoint's ``model.json``.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
from gymnasium import spaces

RESIDUALS = ("", "grid", "grid-tuned")


class RuleResidual(gym.Wrapper):
    """``Discrete(n + 1)``: ``0`` = the grid rule driver's action, ``k`` = the env's ``k - 1``.

    Args:
        env: an env the grid rule driver can drive (``"dict"`` observation with an
            image grid, the speed or discrete meta-actions).
        tuned: drive on top of the tuned rule driver (``rule_based.TUNED_PARAMS``, the
            ``grid-tuned`` driver) instead of the one with default parameters.
    """

    def __init__(self, env: gym.Env, tuned: bool = False) -> None:
        from rule_based import grid_driver

        super().__init__(env)
        if not isinstance(env.action_space, spaces.Discrete):
            raise ValueError(f"--residual grid: needs a Discrete action space, "
                             f"got {env.action_space}")
        self.driver = grid_driver(tuned)
        self.action_space = spaces.Discrete(int(env.action_space.n) + 1)
        self._obs: Any = None

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        self.driver.reset(self.env, 0)  # reads the (possibly reset-changed) env config
        self._obs = obs
        return obs, info

    def rule_action(self) -> int:
        """The rule driver's action for the last observation."""
        if self._obs is None:
            raise RuntimeError("RuleResidual: call reset() first")
        return int(self.driver.act(self._obs, {}))

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        a = int(action)
        if not 0 <= a < self.action_space.n:
            raise ValueError(f"RuleResidual: action {a} not in {self.action_space}")
        obs, reward, terminated, truncated, info = self.env.step(
            self.rule_action() if a == 0 else a - 1)
        self._obs = obs
        info["override"] = a != 0
        return obs, reward, terminated, truncated, info

    def get_action_meanings(self) -> list[str]:
        return ["RULE", *self.env.unwrapped.get_action_meanings()]


def wrap(env: gym.Env, residual: str) -> gym.Env:
    """``env`` itself (``residual == ""``) or wrapped in :class:`RuleResidual` on the
    grid rule driver (``"grid"``) or the tuned one (``"grid-tuned"``)."""
    if residual not in RESIDUALS:
        raise ValueError(f"--residual: expected '', grid or grid-tuned, got {residual!r}")
    return RuleResidual(env, tuned=residual == "grid-tuned") if residual else env


def prefer_rule(model: Any, p_rule: float) -> float:
    """Bias the ``RULE`` logit of a fresh PPO policy so that it starts taking ``RULE``
    with probability ~``p_rule`` (the other logits start near 0: SB3 initialises the
    action head with gain 0.01). Returns the bias added."""
    if not 0.0 < p_rule < 1.0:
        raise ValueError(f"--residual-p-rule: {p_rule} must be in (0, 1)")
    import torch

    n = int(model.action_space.n)
    bias = math.log(p_rule * (n - 1) / (1.0 - p_rule))
    with torch.no_grad():
        model.policy.action_net.bias[0] += bias
    return bias


if __name__ == "__main__":
    raise SystemExit(f"{__file__}: a part of ppo_grid.py, not a script of its own; run "
                     "python baselines/ppo_grid.py --residual grid ... (baselines/README.md)")
