"""Tune the grid rule driver's parameters on validation seeds: a recorded grid search.

The grid rule driver (:class:`rule_based.GridRuleDriver`) was written with hand-set
numbers. A learned driver must be compared with the strongest non-learned driver we
can build, so this script searches its parameters on **validation** seeds (20000 on,
never the held-out evaluation seeds 10000-10099 nor a training map) and writes every
configuration's result, so that the choice can be checked and redone::

    python baselines/tune_rule.py \\
        --env-config '{"reward":{"collision":-30,"off_road":-10},"action":{"repeat":3}}' \\
        --max-episode-steps 200 --episodes 50 --seed 20000 --workers 2 \\
        --grid '{"corridor_static": [0.9, 1.4], "give_way_line": [2, 3],
                 "give_way_moving": [0.35, 0.5], "margin": [4, 6]}' \\
        --out benchmarks/search/rule-driver.json

Selection: the highest success rate minus collision rate on the validation seeds
(ties: fewer collisions, then the first in grid order). Parameters not in ``--grid``
keep their defaults. :data:`rule_based.TUNED_PARAMS` is the best row of the second
stage (``benchmarks/search/rule-driver-stage2.json``: the defaults and the first
stage's five best on 200 more seeds, ``--grid`` given as a list); a test checks it.
"""

from __future__ import annotations

import inspect
import itertools
import json
import math
import shlex
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from rl_common import EnvArgs, atomic_write_text, cli, evaluate_policy, machine_info, make_env
from rl_common import opt, output_file, parse_args, summarize
from rule_based import GridRuleDriver


@dataclass
class Args(EnvArgs):
    """Grid search of the grid rule driver's parameters on validation seeds."""

    grid: str = opt("", "JSON object: parameter -> list of values to try (parameters of "
                        "rule_based.GridRuleDriver), or a list of {parameter: value} "
                        "objects: those configurations ({} = the defaults)")
    episodes: int = opt(50, "validation episodes per configuration, one per seed")
    seed: int = opt(20_000, "first validation seed (episode k uses seed + k)")
    workers: int = opt(1, "processes scoring configurations in parallel")
    out: str = opt("", "write the search (every configuration and the choice) as JSON")


def parameter_defaults() -> dict[str, Any]:
    """The tunable parameters and their defaults: :class:`GridRuleDriver`'s keywords."""
    return {k: p.default for k, p in inspect.signature(GridRuleDriver.__init__).parameters.items()
            if k != "self"}


def parameter_names() -> tuple[str, ...]:
    """The tunable parameters' names."""
    return tuple(parameter_defaults())


def parse_grid(text: str) -> list[dict[str, float]]:
    """``--grid`` JSON -> the configurations: an object of value lists gives their
    cartesian product (in key order); a list of objects gives those configurations
    (a second, longer look at the best few of a first search).

    Raises:
        ValueError: not a JSON object (or list of objects) of known parameters with
            finite positive numbers (non-empty lists in an object).
    """
    try:
        grid = json.loads(text) if text else None
    except json.JSONDecodeError as exc:
        raise ValueError(f"--grid: not valid JSON ({exc})") from None
    if isinstance(grid, list) and grid and all(isinstance(c, dict) for c in grid):
        grid_lists = [{k: [v] for k, v in c.items()} for c in grid]
    elif isinstance(grid, dict) and grid:
        grid_lists = [grid]
    else:
        raise ValueError("--grid: expected a JSON object such as "
                         "'{\"junction_range\": [20, 30]}' or a list of such objects")
    defaults = parameter_defaults()
    configs = []
    for g in grid_lists:
        for key, values in g.items():
            if key not in defaults:
                raise ValueError(f"--grid: unknown parameter {key!r}; known: "
                                 f"{', '.join(defaults)}")
            flag = isinstance(defaults[key], bool)  # give_way: true / false
            top = 1.0 if key.endswith("_moving") else math.inf  # a BetP threshold
            if not isinstance(values, list) or not values or not all(
                    isinstance(v, bool) if flag else (isinstance(v, (int, float))
                                                      and not isinstance(v, bool)
                                                      and math.isfinite(v) and 0 < v <= top)
                    for v in values):
                raise ValueError(f"--grid: {key} needs a non-empty list of "
                                 + ("true / false" if flag else "finite numbers > 0"
                                    + (f" and <= {top:g}" if top < math.inf else ""))
                                 + f", got {values!r}")
        keys = list(g)
        configs += [{k: (v if isinstance(v, bool) else float(v)) for k, v in zip(keys, combo)}
                    for combo in itertools.product(*(g[k] for k in keys))]
    return configs


def score(env_args: dict[str, Any], params: dict[str, float], seeds: list[int]
          ) -> dict[str, float]:
    """The driver with ``params`` on ``seeds``: :func:`rl_common.summarize` of its episodes."""
    env = make_env(EnvArgs(**env_args))
    try:
        return summarize(evaluate_policy(env, GridRuleDriver(**params), seeds))
    finally:
        env.close()


def criterion(summary: dict[str, float]) -> float:
    """What the search maximises: success rate - collision rate."""
    return summary["success"] - summary["collision"]


def best_row(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The chosen row: highest :func:`criterion`, then fewer collisions, then grid order."""
    # rounded: rates are k / n, and 0.80 - 0.12 must tie with 0.74 - 0.06
    return max(rows, key=lambda r: (round(criterion(r["summary"]), 9),
                                    -round(r["summary"]["collision"], 9), -rows.index(r)))


def run(args: Args) -> dict[str, Any]:
    """Score every configuration of ``args.grid``; returns the search record."""
    configs = parse_grid(args.grid)
    if args.episodes < 1:
        raise ValueError(f"--episodes: must be >= 1, got {args.episodes}")
    if args.workers < 1:
        raise ValueError(f"--workers: must be >= 1, got {args.workers}")
    env_args = {k: v for k, v in asdict(args).items() if k in EnvArgs.__dataclass_fields__}
    make_env(EnvArgs(**env_args)).close()  # a bad --env-config fails here, in one line
    seeds = list(range(args.seed, args.seed + args.episodes))
    t0 = time.time()
    if args.workers == 1:
        summaries = [score(env_args, c, seeds) for c in configs]
    else:
        with ProcessPoolExecutor(args.workers) as pool:
            summaries = list(pool.map(score, [env_args] * len(configs), configs,
                                      [seeds] * len(configs)))
    rows = [{"params": c, "summary": s, "criterion": criterion(s)}
            for c, s in zip(configs, summaries)]
    for row in rows:
        s = row["summary"]
        print(f"{json.dumps(row['params'])}: success {s['success']:.2f}, "
              f"collisions {s['collision']:.2f}, off-road {s['off_road']:.2f}")
    best = best_row(rows)
    return {
        "command": shlex.join(["python", "baselines/tune_rule.py", *sys.argv[1:]]),
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "wall_s": round(time.time() - t0, 1),
        "machine": machine_info(),
        "env": env_args,
        "seeds": [seeds[0], seeds[-1]],
        "defaults": parameter_defaults(),
        "criterion": "success - collision (ties: fewer collisions, then grid order)",
        "rows": rows,
        "best": best,
    }


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Command-line entry point; returns the search record."""
    args = parse_args(Args, argv)
    output_file(args.out, "--out", ".json")
    record = run(args)
    best = record["best"]
    print(f"best: {json.dumps(best['params'])} (success {best['summary']['success']:.2f}, "
          f"collisions {best['summary']['collision']:.2f})")
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(args.out, json.dumps(record, indent=1) + "\n")
    return record


if __name__ == "__main__":
    cli(main)
