"""Moving-car density of the `dense` city and what it costs in queues (issue 14).

    python docs/traffic_density.py --cars 60 200

For each car count: road-lane length and moving cars per km of lane (seeds 0-2), the
share of cars faster than 0.5 m/s after 10 s, and the gridlock figure of
``docs/gridlock.py`` (share of vehicle-steps standing still > 20 s outside a planned
halt, seeds 0-2, 60 s; queues at red lights count).
"""

from __future__ import annotations

import argparse

import numpy as np

from dstenv.data.sampling import scenario_config
from dstenv.sim import World
from dstenv.sim.lanes import LaneKind
from dstenv.sim.routing import gridlocked
from dstenv.sim.types import AgentKind


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cars", type=int, nargs="+", default=[60, 200])
    args = ap.parse_args()
    for cars in args.cars:
        cfg = scenario_config("dense", {"world": {"traffic": {"cars": cars}}})["world"]
        per_km, moving = [], []
        for seed in range(3):
            world = World(cfg, seed)
            net, a = world.map.lanes, world.agents
            km = net.length[net.kind == LaneKind.ROAD].sum() / 1000.0
            mobile = (a.kind == AgentKind.CAR) & ~a.parked
            per_km.append(mobile.sum() / km)
            for _ in range(100):
                world.step()
            a = world.agents
            mobile = (a.kind == AgentKind.CAR) & ~a.parked
            moving.append(np.mean(a.speed[mobile] > 0.5))
        runs = [gridlocked(World(cfg, seed=s), 600) for s in range(3)]
        stuck = sum(r[0] for r in runs) / sum(r[1] for r in runs)
        print(f"cars {cars}: {min(per_km):.1f}-{max(per_km):.1f} moving cars per km of road "
              f"lane; after 10 s {min(moving):.2f}-{max(moving):.2f} of them faster than "
              f"0.5 m/s; standing > 20 s: {100 * stuck:.2f} % of vehicle-steps")


if __name__ == "__main__":
    main()
