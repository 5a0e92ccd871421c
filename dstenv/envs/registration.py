"""Gymnasium registration of the ``DSTGrid-*`` environments (called on ``import dstenv``).

Variants are plain keyword arguments of :class:`~dstenv.envs.DSTGridEnv` (Minigrid
style: ``scenario=`` or ``preset=``, so a user's ``config=`` still merges on top)
held in :data:`VARIANTS`; add an entry to register another. Entry points are
strings, so registering imports nothing heavy.
"""

from __future__ import annotations

from typing import Any

__all__ = ["ENTRY_POINT", "RL_GRID", "RL_OBSERVATION", "OCCLUDED_WORLD", "VARIANTS",
           "register_envs"]

ENTRY_POINT = "dstenv.envs.dstgrid:DSTGridEnv"

#: The RL-sized grid: 84 x 84 cells of 1.0 m, the same ~84 m view as the paper's
#: 256 x 256 x 0.33 m grid at 1/9 of the cells (and NatureCNN's native 84 x 84).
RL_GRID: dict[str, Any] = {"height": 84, "width": 84, "cell_size": 1.0}

#: The RL ids' observation: the grid plus the ego state and the route ahead.
RL_OBSERVATION: dict[str, Any] = {"type": "dict"}

#: World settings of the occlusion task: traffic hidden around the ego's route by
#: buildings flush with the sidewalk (few gaps) and parked cars.
OCCLUDED_WORLD: dict[str, Any] = {
    "task": {
        "cross_traffic": 4,  # cars on the side streets of the ego's next junctions
        "parked_near_route": 10,  # parked cars along the route (they hide pedestrians)
        "crossing_pedestrians": 3,  # pedestrians about to step out near the route
    },
    "map": {"building_coverage": 0.95, "setback_max": 1.0, "gap_prob": 0.2},
}

#: env id -> (``DSTGridEnv`` kwargs, ``max_episode_steps`` at 0.1 s per step)
VARIANTS: dict[str, tuple[dict[str, Any], int]] = {
    "DSTGrid-v0": ({}, 600),
    "DSTGrid-Dense-v0": ({"scenario": "dense"}, 600),
    "DSTGrid-Suburb-v0": ({"scenario": "suburb"}, 600),
    "DSTGrid-Parking-v0": ({"scenario": "parking"}, 600),
    "DSTGrid-OSM-v0": ({"scenario": "osm"}, 600),
    "DSTGrid-RL-v0": ({"preset": {"grid": RL_GRID, "observation": RL_OBSERVATION}}, 400),
    "DSTGrid-Continuous-v0": ({"preset": {"grid": RL_GRID, "observation": RL_OBSERVATION,
                                          "action": {"type": "continuous"}}}, 400),
    # the route fixes the turns: speed-only meta-actions, Discrete(3). 60 s: the
    # privileged autopilot, which keeps every junction rule, makes the 100 m of a
    # success in 65 of 100 episodes in 40 s, 91 in 60 s and 96 in 90 s (seeds 500-599,
    # `python docs/autopilot_outcomes.py --steps N`); the rest wait at junctions
    "DSTGrid-Occluded-v0": ({"preset": {"grid": RL_GRID, "observation": RL_OBSERVATION,
                                        "world": OCCLUDED_WORLD, "action": {"type": "speed"}}},
                            600),
    "DSTGrid-Highway-v0": ({"preset": {"source": "highway", "grid": RL_GRID,
                                       "observation": RL_OBSERVATION}}, 200),
}


def register_envs() -> None:
    """Register every id of :data:`VARIANTS` with Gymnasium (idempotent)."""
    from gymnasium.envs.registration import register, registry

    for env_id, (kwargs, max_steps) in VARIANTS.items():
        if env_id in registry:
            continue
        # no passive env checker: gymnasium's (1.x) marks the first reset checked before it
        # runs, so a first reset refused for bad options left every later step failing
        # with "cannot unpack non-iterable NoneType"; the envs pass gymnasium's full
        # check_env in the tests instead
        register(id=env_id, entry_point=ENTRY_POINT, kwargs=kwargs,
                 max_episode_steps=max_steps, disable_env_checker=True)
