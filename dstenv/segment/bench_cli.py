"""``dstenv benchmark``: score DST, FCN-DST and given networks on held-out maps (and,
with ``--kitti``, on real drives) in one report; ``run_cli_benchmark`` is shared with
``dstenv kitti evaluate``."""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path
from typing import Any

from dstenv.segment.cli import check_out

__all__ = ["benchmark_command", "register", "run_cli_benchmark"]


def _sequence_list(text: str) -> list[str]:
    from dstenv.kitti.cli import _sequences  # one rule for sequence names: 3 -> 0003

    return _sequences(text)


def _params_value(text: Any, key: str, row: str) -> Any:
    """``tune.params`` / ``complete.params`` given as JSON (as results.json prints it)
    or ``@FILE``: a JSON file holding the parameters, a segmenter entry, or a whole
    results.json (its ``row`` segmenter is used)."""
    from dstenv.config import CLIError

    if not isinstance(text, str):
        return text
    if text.startswith("@"):
        path = Path(text[1:])
        try:
            value = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError) as exc:
            raise CLIError(f"--set {key}=@{path}: cannot read JSON ({exc})") from None
        if isinstance(value, dict) and "segmenters" in value:
            if row not in value["segmenters"]:
                raise CLIError(f"--set {key}=@{path}: results.json has no {row!r} row")
            value = value["segmenters"][row]
        return value
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        raise CLIError(
            f"--set {key}={text!r}: expected a JSON object, a TOML inline table or @FILE"
        ) from None


def benchmark_command(args: argparse.Namespace) -> str:
    """The command line of a benchmark run, as recorded in its report."""
    parts = ["dstenv", "benchmark"]
    parts += ["--preset", args.preset] if args.preset else []
    parts += ["--protocol", args.protocol] if getattr(args, "protocol", None) else []
    parts += ["--out", args.out]
    parts += ["--data", args.data] if args.data else []
    if getattr(args, "kitti", None):
        parts += ["--kitti", args.kitti, "--sequences", ",".join(args.sequences or [])]
        parts += ["--osm", args.osm] if args.osm else []
        parts += ["--finetune-frames", str(args.finetune_frames)] if args.finetune_frames else []
    for ckpt in args.checkpoint:
        parts += ["--checkpoint", ckpt]
    for item in args.set or []:
        parts += ["--set", item]
    return " ".join(shlex.quote(a) for a in parts)


def run_cli_benchmark(args: argparse.Namespace, split: str = "test", kept: bool = True
                      ) -> dict[str, Any]:
    """Shared by ``dstenv benchmark`` and ``dstenv kitti evaluate``: config, run, print.
    ``kept=False``: ``args.out`` is a scratch folder its caller removes, so the files are
    not announced (the report is printed either way)."""
    from dstenv.data.cli import parse_set
    from dstenv.segment.benchmark import run_benchmark
    from dstenv.segment.presets import preset_config

    check_out(args)
    overrides = parse_set(args.set or [])
    for section, row in (("tune", "dst-tuned"), ("complete", "dst-complete")):
        node = overrides.get(section, {})
        if "params" in node:
            node["params"] = _params_value(node["params"], f"{section}.params", row)
    if getattr(args, "protocol", None):
        overrides["protocol"] = args.protocol
    cfg = preset_config(args.preset or "cpu", overrides)
    results = run_benchmark(
        cfg,
        args.out,
        data_dir=args.data,
        progress=not args.quiet,
        log=(lambda m: None) if args.quiet else print,
        preset=args.preset or "cpu",
        command=benchmark_command(args),
        checkpoints=args.checkpoint,
        split=split,
    )
    out = Path(args.out)
    if getattr(args, "show_report", not args.quiet):  # benchmark --quiet: the files and
        print((out / "results.md").read_text())  # the verdict (kitti evaluate: the report)
    if kept:
        print(f"wrote {out / 'results.json'}, {out / 'results.md'}, {out / 'figures'}/*.png")
    else:
        print("the report is not kept: add --out DIR to keep results.json, results.md and "
              "the figures")
    return results


def _with_real(args: argparse.Namespace, results: dict[str, Any]) -> dict[str, Any]:
    """``--kitti``: score the run's segmenters on real drives, in the same report (its
    options checked by :func:`_check_kitti_flags` before the run)."""
    from dstenv.config import CLIError
    from dstenv.segment import report
    from dstenv.segment.real import real_benchmark

    if results["data"].get("evaluation_only"):
        raise CLIError("--kitti adds real drives to a simulated benchmark; --data is "
                       "evaluation-only data already (score it with dstenv benchmark --data)")
    out = Path(args.out)
    real = real_benchmark(results, out, args.kitti, args.sequences, args.osm,
                          args.finetune_frames, progress=not args.quiet,
                          log=(lambda m: None) if args.quiet else print)
    results["kitti"] = {k: real[k] for k in ("real", "data", "segmenters", "unscored",
                                             "real_goal")}
    report.write_json(out / "results.json", results)
    section = report.markdown_table({**real, "command": None})
    section = "\n".join(("#" + line) if line.startswith("#") else line
                        for line in section.splitlines())
    md = (out / "results.md").read_text()
    (out / "results.md").write_text(md.rstrip("\n") + "\n\n" + section + "\n")
    print(section)
    return results


def _evaluation_only(data: str) -> bool:
    """Whether the dataset ``data`` is scored without training (no train frames, or a
    KITTI conversion), read from its manifest; False when that cannot be read (the
    benchmark's own checks then name the problem)."""
    from dstenv.data.manifest import load_manifest

    try:
        m = load_manifest(data, verify="none")
    except (OSError, ValueError):
        return False
    kitti = m.get("meta", {}).get("command") == "kitti convert"
    return kitti or not m.get("splits", {}).get("train", {}).get("frames", 0)


def _check_kitti_flags(args: argparse.Namespace) -> None:
    """The ``--kitti`` options, before any stage runs (not after the whole benchmark)."""
    from dstenv.config import CLIError

    if not args.kitti:
        given = [f for f, v in (("--sequences", args.sequences), ("--osm", args.osm),
                                ("--finetune-frames", args.finetune_frames)) if v]
        if given:
            raise CLIError(f"{given[0]} goes with --kitti ROOT (the real drives to score)")
        return
    if not args.sequences:
        raise CLIError("--kitti needs --sequences LIST (e.g. 0003)")
    if args.data and _evaluation_only(args.data):
        raise CLIError("--kitti adds real drives to a simulated benchmark; --data is "
                       "evaluation-only data already (score it with dstenv benchmark --data)")
    if not Path(args.kitti).is_dir():
        raise CLIError(f"--kitti {args.kitti}: no such folder (KITTI tracking's root, holding "
                       "training/velodyne/...)")
    if args.osm and not Path(args.osm).is_file():
        raise CLIError(f"--osm {args.osm}: no such file")
    if args.finetune_frames is not None and args.finetune_frames < 0:
        raise CLIError(f"--finetune-frames must be >= 0, got {args.finetune_frames}")
    from dstenv.kitti.sequence import KittiSequence

    for name in args.sequences:  # the real drives are read now, not after the simulated run
        try:
            KittiSequence(args.kitti, name)
        except (OSError, ValueError) as exc:
            raise CLIError(f"--kitti {args.kitti}: {exc}") from None


def _benchmark(args: argparse.Namespace) -> int:
    _check_kitti_flags(args)
    results = run_cli_benchmark(args)
    if args.kitti:
        results = _with_real(args, results)
    goal = results.get("goal")
    ok = goal is None or (goal["margin_met"] and goal["moving_met"] and goal["static_met"])
    if goal is not None and (args.check_goal or args.quiet):
        missed = [name for name in ("margin", "moving", "static") if not goal[f"{name}_met"]]
        verdict = ("met" if ok else f"NOT met ({', '.join(missed)}; {args.out}/results.md, "
                   "section Goal)")
        print(f"goal: {goal['best_learned']} vs {goal['best_baseline']} on the simulated test "
              f"maps: {verdict}", file=sys.stderr if not ok and args.check_goal else sys.stdout)
    return 0 if ok or not args.check_goal else 1


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``dstenv benchmark`` to the CLI."""
    from dstenv.segment.presets import PRESETS

    b = sub.add_parser(
        "benchmark",
        help="compare DST and FCN-DST segmenters on held-out maps",
        description="Generate data, train the learned segmenters, tune DST, and score every "
        "segmenter on a test split of unseen map seeds. Writes results.md, "
        "results.json and figures/*.png into --out. Rerun to resume. On evaluation-only "
        "data (--data from dstenv kitti convert, or without a train split) nothing is "
        "trained or tuned: DST is scored from the stored grids and the --checkpoint "
        "networks (e.g. trained on simulated data) on the stored frames.",
    )
    b.add_argument(
        "--preset",
        default=None,
        choices=sorted(PRESETS),
        help="cpu: <= 30 min on a 2-core CPU (default); gpu: the full benchmark (3 seeds); "
        "curve: training-set sizes 140/1400/14000; smoke: every stage in about a minute "
        "(CI); tiny: the test suite's run",
    )
    b.add_argument(
        "--protocol",
        choices=("sim", "paper"),
        default=None,
        help="paper: the paper's protocol for the generated data (1 Hz fusion, camera-FOV "
        "labels, KITTI moving rule, imperfect map; docs/benchmark.md)",
    )
    b.add_argument("--out", default="benchmark-out", metavar="DIR", help="output directory")
    b.add_argument("--data", metavar="DIR", help="use existing shards instead of generating")
    b.add_argument(
        "--checkpoint",
        action="append",
        default=[],
        metavar="PT",
        help="also score this trained network (dstenv train); repeatable",
    )
    b.add_argument(
        "--set",
        action="append",
        metavar="KEY=VALUE",
        help="override a preset value, e.g. train.epochs=3 or data.frames=500; "
        "tune.params / complete.params also take JSON or @results.json (repeatable)",
    )
    b.add_argument("--kitti", metavar="ROOT",
                   help="also score the run's segmenters on these real KITTI tracking drives "
                   "(converted into OUT/kitti; a section of the same report)")
    b.add_argument("--sequences", type=_sequence_list, metavar="LIST",
                   help="KITTI sequences for --kitti, e.g. 0003,0005")
    b.add_argument("--osm", metavar="FILE", help="OpenStreetMap file for --kitti (default: no map)")
    b.add_argument("--finetune-frames", type=int, default=0, metavar="N",
                   help="with --kitti: fine-tune the best network on the first N labelled frames "
                   "of each sequence and score every row from frame N+10 on")
    b.add_argument("--check-goal", action="store_true", help="exit 1 if the README goal is not met")
    b.add_argument("--quiet", action="store_true",
                   help="no progress and no report on the terminal: the files written and the "
                   "goal's verdict only (the report is in --out's results.md)")
    b.set_defaults(func=_benchmark)
