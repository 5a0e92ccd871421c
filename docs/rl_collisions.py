"""Where and how RL drivers collide on ``DSTGrid-Occluded-v0`` (issue 17's collision goal).

For each held-out seed that ends in a collision, the state at the collision: ego speed
(and its speed 3 s before), the next-junction distance of the observation, the nearest
road user (kind, speed, heading relative to the ego, position in the ego frame) and a
class of the crash: ``crossing`` (headings 30-150 deg apart), ``rear-end`` (the other
ahead, headings within 30 deg), ``head-on`` (more than 150 deg), ``pedestrian`` /
``cyclist`` by kind::

    python docs/rl_collisions.py --policy grid --episodes 100 --out F.json
    python docs/rl_collisions.py --policy CHECKPOINT.pt --episodes 100 --out F.json

Both in PPO's training config (``action.repeat = 3``, collision -30, off-road -10, 200
steps of 0.3 s), the seeds of ``baselines/evaluate.py`` (10000 on).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "baselines"))

import dstenv  # noqa: E402,F401  (registers the ids)
from dstenv.envs.navigation import EGO_FEATURES, JUNCTION_RANGE  # noqa: E402
from dstenv.sim.types import AgentKind  # noqa: E402

CONFIG = {"reward": {"collision": -30, "off_road": -10}, "action": {"repeat": 3}}


def _crash(world, ego_speed: float) -> dict:
    ego = np.asarray(world.ego_pose, dtype=np.float64)
    ag = world.agents
    rel = ag.xy - ego[:2]
    k = int(np.argmin(np.hypot(*rel.T)))
    c, s = np.cos(ego[2]), np.sin(ego[2])
    ex, ey = c * rel[k, 0] + s * rel[k, 1], -s * rel[k, 0] + c * rel[k, 1]
    dyaw = abs((float(ag.yaw[k]) - ego[2] + np.pi) % (2 * np.pi) - np.pi)
    kind = AgentKind(int(ag.kind[k])).name.lower()
    if kind in ("pedestrian", "cyclist"):
        what = kind
    elif dyaw < np.radians(30):
        what = "rear-end" if ex > 0 else "hit from behind"
    elif dyaw > np.radians(150):
        what = "head-on"
    else:
        what = "crossing"
    return {"kind": kind, "class": what, "other_speed": round(float(ag.speed[k]), 2),
            "rel_yaw_deg": round(float(np.degrees(dyaw)), 1),
            "other_ego_frame": [round(float(ex), 2), round(float(ey), 2)],
            "ego_speed": round(ego_speed, 2)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--policy", required=True, help="grid (the rule driver) or a model.pt")
    ap.add_argument("--episodes", type=int, default=100)
    ap.add_argument("--seed", type=int, default=10_000)
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    from evaluate import PPOPolicy
    from rl_common import EnvArgs, make_env
    from rule_based import GridRuleDriver

    # the env and the policies exactly as baselines/evaluate.py builds them
    env_args = EnvArgs(env_config=json.dumps(CONFIG), max_episode_steps=200)
    if args.policy == "grid":
        policy: Any = GridRuleDriver()
        env = make_env(env_args)
    else:
        policy = PPOPolicy(args.policy)  # deterministic, as evaluate.py's default
        env = policy.make_env(env_args)
    jd = EGO_FEATURES.index("junction_dist")
    crashes, outcomes = [], Counter()
    for seed in range(args.seed, args.seed + args.episodes):
        obs, info = env.reset(seed=seed)
        policy.reset(env, seed)
        speeds = []
        while True:
            obs, _, term, trunc, info = env.step(policy.act(obs, info))
            w = env.unwrapped.pipeline.world
            speeds.append(float(w.ego_speed))
            if term or trunc:
                break
        outcomes[info["termination_reason"]] += 1
        if info["termination_reason"] == "collision":
            row = {"seed": seed, "step": len(speeds), **_crash(w, speeds[-1]),
                   "ego_speed_3s_before": round(speeds[max(0, len(speeds) - 11)], 2),
                   "junction_dist_m": round(float(obs["ego"][jd]) * JUNCTION_RANGE, 1)}
            crashes.append(row)
            print(row)
    env.close()
    summary = {"outcomes": dict(outcomes), "classes": dict(Counter(c["class"] for c in crashes)),
               "at_junction (< 5 m)": sum(c["junction_dist_m"] < 5 for c in crashes),
               "ego_speed_median": float(np.median([c["ego_speed"] for c in crashes]))
               if crashes else None}
    print(summary)
    Path(args.out).write_text(json.dumps(
        {"command": " ".join(["python", "docs/rl_collisions.py", *sys.argv[1:]]),
         "config": CONFIG, "summary": summary, "crashes": crashes}, indent=1) + "\n")


if __name__ == "__main__":
    main()
