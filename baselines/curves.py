"""Learning curves of PPO runs: success, collision and off-road rates against env steps.

Reads the ``episodes.csv`` of each run directory given (one per training seed,
written by :mod:`ppo_grid`), bins the finished training episodes by the env step at
which they ended (``--bin`` steps per bin), and plots per rate the mean over seeds
with the spread (min..max) as a band. Evaluation CSVs (``--reference``, from
``evaluate.py --csv`` or the drivers' ``--csv``) add each reference driver's rate
as a horizontal line. Run::

    python baselines/curves.py --runs runs/ppo_s0 runs/ppo_s1 runs/ppo_s2 \\
        --reference runs/eval.csv --out baselines/learning_curves.png
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dstenv.io import png_path
from rl_common import check_once, cli, opt, parse_args

RATES = ("success", "collision", "off_road")


@dataclass
class Args:
    """Plot learning curves of PPO runs."""

    runs: list[str] = opt([], "run directories holding episodes.csv (one per seed)")
    reference: list[str] = opt([], "evaluation CSVs: policy rates drawn as lines")
    bin: int = opt(2000, "[env steps] width of a bin")
    max_steps: int = opt(0, "[env steps] plot up to here; 0 = the shortest run")
    out: str = opt("runs/learning_curves.png", "output PNG (the committed figures in "
                                                "baselines/ are written only when named)")


def binned_rates(path: str | Path, width: int, max_steps: int) -> dict[str, np.ndarray]:
    """Per-bin rates of one run: ``{rate: (B,) float64}`` (NaN: no episode ended in the
    bin) and ``"episodes"`` ``(B,)``; bin ``b`` covers steps ``(b w, (b + 1) w]``."""
    rows = list(csv.DictReader(open(Path(path) / "episodes.csv")))
    n_bins = max(int(np.ceil(max_steps / width)), 1)
    steps = np.array([int(r["timesteps"]) for r in rows])
    b = np.clip((steps - 1) // width, 0, None)
    keep = b < n_bins
    out = {"episodes": np.bincount(b[keep], minlength=n_bins).astype(float)}
    for rate in RATES:
        v = np.array([float(r[rate]) for r in rows])
        total = np.bincount(b[keep], weights=v[keep], minlength=n_bins)
        with np.errstate(invalid="ignore", divide="ignore"):
            out[rate] = np.where(out["episodes"] > 0, total / out["episodes"], np.nan)
    return out


def reference_rates(paths: list[str]) -> dict[str, dict[str, float]]:
    """``{policy: {rate: value}}`` from evaluation CSVs (one row per episode); a policy
    name found in several files is one line per file, named with the file's stem (the
    files may hold other env configs: they are never pooled).

    Raises:
        ValueError: a file that is not an ``evaluate.py --csv`` file (one line).
    """
    acc: dict[tuple[str, str], dict[str, list[float]]] = {}
    for p in paths:
        with open(p, encoding="utf-8-sig") as fh:
            rows = list(csv.DictReader(fh))
        missing = [c for c in ("policy", *RATES) if rows and c not in rows[0]]
        if not rows or missing:
            raise ValueError(f"--reference {p}: not an evaluate.py --csv file ("
                             + (f"no column {missing[0]!r})" if rows else "no rows)"))
        for r in rows:
            d = acc.setdefault((r["policy"], str(p)), {k: [] for k in RATES})
            for k in RATES:
                d[k].append(float(r[k] in ("True", "1")))
    names = [n for n, _ in acc]
    stems = [Path(p).stem for p in dict.fromkeys(p for _, p in acc)]
    tag = (lambda p: Path(p).stem) if len(set(stems)) == len(stems) else str  # a/eval, b/eval
    return {(name if names.count(name) == 1 else f"{name} ({tag(p)})"):
            {k: float(np.mean(v)) for k, v in d.items()} for (name, p), d in acc.items()}


#: a run's arguments that do not change what it learns (seeds of one recipe may differ)
NOT_RECIPE = {"seed", "out", "verbose", "tensorboard", "checkpoint_every", "keep_checkpoints",
              "torch_threads", "vec_env"}
#: those that say which env it learnt in: seeds of other envs are never one curve
ENV_ARGS = ("env_id", "env_config", "max_episode_steps", "map_pool")


def check_runs(runs: list[str]) -> None:
    """Refuse a run given twice and runs of other envs as the seeds of one curve (their
    ``model.json``); print a note for other differences of the recipe.

    Raises:
        ValueError: one line naming the runs and the argument.
    """
    check_once(runs, "--runs", ": one seed, counted as two")
    metas = {}
    for d in runs:
        try:
            metas[d] = json.loads((Path(d) / "model.json").read_text())["args"]
        except (OSError, ValueError, KeyError, TypeError):
            continue  # a run without its first checkpoint yet: nothing to compare
    first = next(iter(metas), None)
    for d, args in metas.items():
        for k in sorted(set(args) | set(metas[first])):
            a, b = metas[first].get(k), args.get(k)
            if a == b or k in NOT_RECIPE:
                continue
            if k in ENV_ARGS:
                raise ValueError(f"--runs: {first} and {d} learnt in other envs (--"
                                 f"{k.replace('_', '-')} {a!r} vs {b!r}); plot each env's "
                                 "seeds on their own")
            print(f"note: {first} and {d} differ in --{k.replace('_', '-')} ({a!r} vs {b!r})")


def plot(args: Args) -> Path:
    """Write the PNG; returns its path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not args.runs:
        raise ValueError("--runs: give at least one run directory")
    png_path(args.out, "--out")  # a .png name (a folder or 'c10' was written as c10.png)
    check_runs(args.runs)
    last = []
    for d in args.runs:
        with open(Path(d) / "episodes.csv") as fh:
            steps = [int(r["timesteps"]) for r in csv.DictReader(fh)]
        if not steps:
            raise ValueError(f"--runs {d}: episodes.csv has no finished episode yet")
        last.append(max(steps))
    if args.max_steps < 0:
        raise ValueError(f"--max-steps must be >= 0 (0: the shortest run's), got {args.max_steps}")
    max_steps = args.max_steps or min(last)
    if args.bin < 1 or args.bin > max_steps:
        raise ValueError(f"--bin {args.bin}: give 1 .. {max_steps} env steps (the shortest "
                         "run's last finished episode), so that a bin holds episodes")
    per_run = [binned_rates(d, args.bin, max_steps) for d in args.runs]
    x = (np.arange(len(per_run[0]["episodes"])) + 1) * args.bin
    refs = reference_rates(args.reference)
    fig, axes = plt.subplots(1, len(RATES), figsize=(5 * len(RATES), 3.8), sharex=True)
    for ax, rate in zip(axes, RATES):
        y = np.stack([r[rate] for r in per_run])
        with np.errstate(all="ignore"):
            ax.fill_between(x, np.nanmin(y, 0), np.nanmax(y, 0), alpha=0.25,
                            label=f"PPO min..max over {len(per_run)} seeds")
            ax.plot(x, np.nanmean(y, 0), lw=2, label="PPO mean (training episodes)")
        for k, (name, vals) in enumerate(refs.items()):
            ax.axhline(vals[rate], ls="--", lw=1, color=f"C{k + 2}", label=name)
        ax.set_title(rate.replace("_", "-") + " rate")
        ax.set_xlabel("env steps")
        ax.set_ylim(-0.02, 1.02)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, loc="best")
    fig.tight_layout()
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def main(argv: list[str] | None = None) -> Path:
    """Command-line entry point; prints and returns the PNG path."""
    path = plot(parse_args(Args, argv))
    print(path)
    return path


if __name__ == "__main__":
    cli(main)
