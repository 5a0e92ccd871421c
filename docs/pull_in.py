"""Draw a car pulling into a kerbside space (issue 12) in a generated city.

Writes ``docs/img/pull-in.png``: four top views of the same street, from the moment a
car decides to park to the step it is parked (red: moving, blue: static), with its
path so far as a line::

    python docs/pull_in.py --out docs/img/pull-in.png
    python docs/pull_in.py --stats   # pull-ins of the default scenario, 3 x 300 s
    python docs/pull_in.py --bench   # world step cost, pull_in_rate 0 vs 0.01 (paired)

The city is the ``default`` scenario's 3 x 3 blocks with a high ``pull_in_rate``
(0.05 1/s, so that a pull-in comes early); the first car that parks is drawn. The run
is seeded: the same command draws the same picture.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from dstenv.scenario_files import load_scenario
from dstenv.sim import World, default_config
from dstenv.sim.cli import draw_legend, draw_world

CONFIG = {"map": {"blocks_x": 3, "blocks_y": 3}, "traffic": {"pull_in_rate": 0.05}}


def first_pull_in(seed: int, max_steps: int = 1500) -> tuple[int, int, int]:
    """``(row, step it decided, step it was parked)`` of the first car that parks."""
    w = World(_config(), seed=seed)
    st = w._state
    start: dict[int, int] = {}
    for step in range(1, max_steps + 1):
        was = st["park"][:, 0] >= 0
        w.step()
        for i in np.flatnonzero(st["park"][:, 0] >= 0):
            start.setdefault(int(i), step)
        done = np.flatnonzero(was & st["parked"])
        if len(done):
            i = int(done[0])
            return i, start[i], step
    raise RuntimeError(f"no car parked in {max_steps} steps (seed {seed})")


def _config() -> dict:
    cfg = load_scenario("default", {"world": default_config()})["world"]
    cfg["map"].update(CONFIG["map"])
    cfg["traffic"].update(CONFIG["traffic"])
    return cfg


def stats(scenario: str, seeds: range, steps: int) -> dict[str, float]:
    """Pull-ins of a shipped scenario at its default ``pull_in_rate``: decisions (by
    eligible cars), how many found a space, cars parked, per minute and per car."""
    from dstenv.sim import pullin

    cfg = load_scenario(scenario, {"world": default_config()})["world"]
    found = tried = parked = 0
    elig_s = 0.0  # eligible car-seconds
    real = pullin.find_space

    def counting(*a):
        nonlocal found, tried
        tried += 1
        out = real(*a)
        found += out is not None
        return out

    pullin.find_space = counting
    try:
        for seed in seeds:
            w = World(cfg, seed=seed)
            st = w._state
            for _ in range(steps):
                was = st["park"][:, 0] >= 0
                elig_s += w.config["dt"] * sum(pullin.eligible(st, w.map, i)
                                               for i in range(len(st["v"]) - 1))
                w.step()
                parked += int((was & st["parked"]).sum())
    finally:
        pullin.find_space = real
    minutes = len(seeds) * steps * cfg["dt"] / 60.0
    return {"decisions": tried, "found": found, "found_share": found / max(tried, 1),
            "parked": parked, "parked_per_min": parked / minutes,
            "eligible_cars_mean": elig_s / (minutes * 60.0),
            "minutes_to_park": elig_s / 60.0 / max(parked, 1)}


def step_cost(rounds: int = 40) -> tuple[float, float]:
    """Median world step [ms] of the ``dstenv bench world`` city with ``pull_in_rate`` 0
    and 0.01, paired: each round steps two deep copies of one state (alternating which
    goes first), so both time the same traffic."""
    import copy
    import time

    from dstenv.sim.bench import BENCH_CONFIG

    cfg = {"map": dict(BENCH_CONFIG["map"]),
           "traffic": {**BENCH_CONFIG["traffic"], "pull_in_rate": 0.01}}
    base = World(cfg, seed=0)
    for _ in range(20):
        base.step()
    times: dict[float, list[float]] = {0.0: [], 0.01: []}
    for rnd in range(rounds):
        for rate in ((0.0, 0.01) if rnd % 2 else (0.01, 0.0)):
            w = copy.deepcopy(base)
            w.config["traffic"]["pull_in_rate"] = rate
            w.step()
            for _ in range(30):
                t0 = time.perf_counter()
                w.step()
                times[rate].append(time.perf_counter() - t0)
        for _ in range(10):
            base.step()
    return float(np.median(times[0.0]) * 1e3), float(np.median(times[0.01]) * 1e3)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="docs/img/pull-in.png")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--stats", action="store_true",
                    help="print pull-in figures of the default scenario instead (3 x 300 s)")
    ap.add_argument("--bench", action="store_true",
                    help="print the world step cost of pull-ins (rate 0 vs 0.01, paired)")
    args = ap.parse_args(argv)
    if args.bench:
        off, on = step_cost()
        print(f"world step (bench world city): pull_in_rate 0: {off:.3f} ms, 0.01: {on:.3f} ms,"
              f" ratio {on / off:.3f}")
        return 0
    if args.stats:
        for k, v in stats("default", range(3), 3000).items():
            print(f"{k}: {v:.3g}")
        return 0
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    row, t0, t1 = first_pull_in(args.seed)
    shots = np.linspace(t0, t1, 4).round().astype(int)
    w = World(_config(), seed=args.seed)
    fig, axes = plt.subplots(1, 4, figsize=(18, 4.4))
    path, k = [], 0
    for step in range(1, t1 + 1):
        w.step()
        path.append(w.agents.xy[row].copy())
        if step == shots[k]:
            ax = axes[k]
            draw_world(ax, w)
            p = np.array(path[max(0, t0 - 40 - 1):])
            ax.plot(p[:, 0], p[:, 1], "-", c="k", lw=0.8)
            if k == 0:
                tgt = w._state["park"][row].copy()
            a = w.agents
            cx, cy = a.xy[row]
            ax.set_title(f"t = {w.time:.1f} s, speed {a.speed[row]:.1f} m/s"
                         + (" (parked)" if a.parked[row] else ""), fontsize=9)
            ax.plot([cx], [cy], "k+", ms=6)
            k += 1
    # the same window in all panels: around where the car parked
    cx, cy = w.agents.xy[row]
    for ax in axes:
        ax.set_xlim(cx - 22, cx + 22)
        ax.set_ylim(cy - 14, cy + 14)
    draw_legend(axes[-1], lidar=False)
    axes[-1].get_legend().set_bbox_to_anchor((1.02, 1.0))
    axes[-1].get_legend()._loc = 2  # upper left, outside the last panel
    fig.suptitle(f"a car pulls into a kerbside space (row {row}, seed {args.seed}; target "
                 f"{tgt[0]:.1f} m along its lane, {tgt[1]:.2f} m to the side)", fontsize=10)
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}: row {row}, decided at step {t0}, parked at step {t1}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
