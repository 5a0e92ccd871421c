"""Shared settings of the RL-baseline tests: the scripts in ``baselines/`` are run
through their ``main`` functions on a small city, short episodes and tiny budgets.

No ``__init__.py`` here on purpose: a test package named ``baselines`` would shadow
the top-level ``baselines/`` directory for everyone in the session.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

BASELINES = Path(__file__).resolve().parents[2] / "baselines"
if str(BASELINES) not in sys.path:  # the scripts import their sibling rl_common
    sys.path.insert(0, str(BASELINES))

#: a tiny warm-started PPO run: two dummy envs, DAgger from the grid rule driver for 120
#: env steps in two rounds (a later ``--warm-start`` flag overrides the teacher)
TINY_WARM = ["--n-envs", "2", "--vec-env", "dummy", "--n-steps", "32", "--batch-size", "32",
             "--map-pool", "2", "--verbose", "0", "--warm-start", "grid",
             "--warm-start-steps", "120", "--warm-start-rounds", "2"]

#: A small city and grid (40 x 40 is above NatureCNN's 36 x 36 minimum).
SMALL_CONFIG = {
    "grid": {"height": 40, "width": 40, "cell_size": 1.0},
    "lidar": {"beams": 360},
    "world": {"map": {"blocks_x": 3, "blocks_y": 3}},
}


@pytest.fixture
def small_config() -> dict:
    return json.loads(json.dumps(SMALL_CONFIG))


@pytest.fixture
def env_flags() -> list[str]:
    """Flags shared by every script: the occlusion task on the small config, 30 steps."""
    return ["--env-id", "DSTGrid-Occluded-v0", "--env-config", json.dumps(SMALL_CONFIG),
            "--max-episode-steps", "30"]
