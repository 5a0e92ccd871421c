"""Compare two drivers episode by episode on the same seeds (a paired test).

Two drivers scored on the same seeds (``evaluate.py --csv``) share every world, so the
fair question is not "which rate is higher" but "in how many episodes does each one
do better than the other". For success and for collision this prints the rates, the
discordant episodes (A only, B only) and the exact two-sided McNemar p-value (a
binomial test on the discordant pairs)::

    python baselines/compare.py --a benchmarks/results/rl/eval-grid-r3.csv \\
        --b benchmarks/results/rl/eval-ppo-route-s0-450k.csv

Each file must hold one policy (or name it with ``--policy-a`` / ``--policy-b``); only
seeds present in both are compared, and the count is printed. Files that record their
env (the id, ``--env-config`` and time limit in every row) must agree on it.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rl_common import ENV_COLUMNS, cli, opt, parse_args

OUTCOMES = ("success", "collision", "off_road")


@dataclass
class Args:
    """Compare two drivers episode by episode on the same seeds."""

    a: str = opt("", "CSV of driver A (evaluate.py --csv)")
    b: str = opt("", "CSV of driver B")
    policy_a: str = opt("", "the policy of file A to use (empty: its only one)")
    policy_b: str = opt("", "the policy of file B to use (empty: its only one)")


def read_episodes(path: str, policy: str = "") -> tuple[str, dict[int, dict[str, bool]]]:
    """One policy's episodes of an ``evaluate.py --csv`` file: ``(policy, {seed: outcomes})``.

    Raises:
        FileNotFoundError: no such file; ValueError: not such a CSV, or the policy is
            missing or ambiguous.
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    try:
        with p.open(newline="", encoding="utf-8-sig") as fh:  # -sig: a spreadsheet's BOM
            rows = list(csv.DictReader(fh))
    except (UnicodeDecodeError, csv.Error) as exc:
        raise ValueError(f"{path}: not a CSV text file ({type(exc).__name__}); give an "
                         "evaluate.py --csv file") from None
    need = {"policy", "seed", *OUTCOMES}
    if not rows or not need <= set(rows[0]):
        raise ValueError(f"{path}: not an evaluate.py --csv file (needs columns "
                         f"{', '.join(sorted(need))})")
    names = list(dict.fromkeys(r["policy"] for r in rows))
    if not policy:
        if len(names) != 1:
            raise ValueError(f"{path}: holds {len(names)} policies ({'; '.join(names)}); "
                             "pick one with --policy-a / --policy-b")
        policy = names[0]
    elif policy not in names:
        raise ValueError(f"{path}: no policy {policy!r}; it has: {'; '.join(names)}")
    out: dict[int, dict[str, bool]] = {}
    for line, r in enumerate(rows, start=2):  # line 1 is the header
        if r["policy"] != policy:
            continue
        try:
            seed = int(r["seed"])
        except (TypeError, ValueError):
            raise ValueError(f"{path}, line {line}: seed {r['seed']!r} is not an integer") from None
        bad = [k for k in OUTCOMES if r[k] not in ("True", "False")]
        if bad:
            raise ValueError(f"{path}, line {line}: {bad[0]} {r[bad[0]]!r} is not True or False")
        if seed in out:
            raise ValueError(f"{path}, line {line}: seed {seed} of {policy!r} a second time")
        out[seed] = {k: r[k] == "True" for k in OUTCOMES}
    return policy, out


def read_env(path: str, policy: str) -> tuple[str, ...] | None:
    """The env ``policy``'s episodes in ``path`` were driven in (the CSV's
    :data:`rl_common.ENV_COLUMNS`), or None for a file written before they existed.

    Raises:
        ValueError: the policy's rows name more than one env.
    """
    with Path(path).open(newline="", encoding="utf-8-sig") as fh:
        rows = [r for r in csv.DictReader(fh) if r.get("policy") == policy]
    if not rows or not set(ENV_COLUMNS) <= set(rows[0]):
        return None
    envs = {tuple(r[k] for k in ENV_COLUMNS) for r in rows}
    if len(envs) > 1:
        raise ValueError(f"{path}: the episodes of {policy!r} come from {len(envs)} envs")
    return envs.pop()


def check_same_env(a: tuple[str, ...] | None, b: tuple[str, ...] | None) -> str:
    """Refuse two files scored in different envs (a paired test of other worlds); the
    note to print when a file does not say (``""``: both agree)."""
    if a is None or b is None:
        return ("note: " + ("A" if a is None else "B") + " does not record its env (an older "
                "CSV): check that both were scored with the same --env-id, "
                "--env-config and --max-episode-steps")
    for k, x, y in zip(ENV_COLUMNS, a, b):
        if x != y:
            raise ValueError(f"A and B were scored in different envs ({k}: {x} vs {y}); "
                             "compare drivers evaluated with the same --env-id, --env-config "
                             "and --max-episode-steps")
    return ""


def mcnemar_p(only_a: int, only_b: int) -> float:
    """Exact two-sided McNemar p-value: under "no difference" each discordant episode
    goes either way with probability 1/2 (1.0 when there is none)."""
    n = only_a + only_b
    if n == 0:
        return 1.0
    k = min(only_a, only_b)
    tail = sum(math.comb(n, i) for i in range(k + 1)) / 2 ** n
    return min(1.0, 2 * tail)


def compare(a: dict[int, dict[str, bool]], b: dict[int, dict[str, bool]]) -> dict[str, Any]:
    """Per outcome: rates over the common seeds, discordant counts and McNemar's p."""
    seeds = sorted(set(a) & set(b))
    if not seeds:
        raise ValueError("the two files share no seed")
    out: dict[str, Any] = {"episodes": len(seeds)}
    for k in OUTCOMES:
        only_a = sum(a[s][k] and not b[s][k] for s in seeds)
        only_b = sum(b[s][k] and not a[s][k] for s in seeds)
        out[k] = {"a": sum(a[s][k] for s in seeds) / len(seeds),
                  "b": sum(b[s][k] for s in seeds) / len(seeds),
                  "only_a": only_a, "only_b": only_b, "p": mcnemar_p(only_a, only_b)}
    return out


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Command-line entry point; returns :func:`compare`'s result with the names."""
    args = parse_args(Args, argv)
    if not args.a or not args.b:
        raise ValueError("--a and --b: two evaluate.py --csv files are needed")
    name_a, a = read_episodes(args.a, args.policy_a)
    name_b, b = read_episodes(args.b, args.policy_b)
    note = check_same_env(read_env(args.a, name_a), read_env(args.b, name_b))
    if note:
        print(note)
    res = compare(a, b)
    dropped = len(a) + len(b) - 2 * res["episodes"]
    print(f"A = {name_a} ({args.a})\nB = {name_b} ({args.b})\n"
          f"{res['episodes']} common seeds"
          + (f" (left out: {len(a) - res['episodes']} seeds of A only, "
             f"{len(b) - res['episodes']} of B only)" if dropped else "") + "\n")
    print("| outcome | A | B | episodes A only | episodes B only | McNemar p |")
    print("|---|---:|---:|---:|---:|---:|")
    for k in OUTCOMES:
        r = res[k]
        print(f"| {k} | {r['a']:.0%} | {r['b']:.0%} | {r['only_a']} | {r['only_b']} | "
              f"{r['p']:.3g} |")
    return {"a": name_a, "b": name_b, **res}


if __name__ == "__main__":
    cli(main)
