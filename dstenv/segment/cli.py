"""``dstenv train`` and ``dstenv benchmark``: fit a segmenter, compare all segmenters."""

from __future__ import annotations

import argparse
import json
import shlex
from pathlib import Path
from typing import Any

__all__ = ["register"]


def _json_arg(text: str) -> dict[str, Any]:
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        raise argparse.ArgumentTypeError(f"not valid JSON: {exc.msg}") from None
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError("expected a JSON object, e.g. '{\"base\": 16}'")
    return value


def _sequence_list(text: str) -> list[str]:
    from dstenv.kitti.cli import _sequences  # one rule for sequence names: 3 -> 0003

    return _sequences(text)


def _apart(args: argparse.Namespace) -> None:
    """Refuse an ``--out`` whose files would mix with others': one that is, or lies inside,
    a dataset (the ``--data`` one or any other: a later generate would take the folder)
    or an input folder (``--data``, ``--kitti``, ``--root``)."""
    from dstenv.config import CLIError
    from dstenv.io import output_folder

    inputs = tuple((flag, v) for flag, v in (("--data", getattr(args, "data", None)),
                                            ("--kitti", getattr(args, "kitti", None)),
                                            ("--root", getattr(args, "root", None))) if v)
    try:
        output_folder(args.out, "--out", inputs=inputs)
    except ValueError as exc:
        raise CLIError(str(exc)) from None


def _train(args: argparse.Namespace) -> int:
    from dstenv.config import CLIError
    from dstenv.data import ShardDataset, StreamingDataset
    from dstenv.data.lock import DatasetLocked, dataset_lock
    from dstenv.segment.checkpoint import training_data
    from dstenv.segment.train import default_train_config, train

    _apart(args)
    defaults = default_train_config()  # --model and --inputs: None when not given
    cfg: dict[str, Any] = {
        "model": args.model or defaults["model"],
        "model_kwargs": args.model_kwargs,
        "seed": args.seed,
        "device": args.device,
        "inputs": args.inputs or defaults["inputs"],
        "labels": args.labels,
    }
    for key in ("epochs", "batch_size", "lr", "loss", "crop", "flip", "num_workers",
                "weight_power"):
        if getattr(args, key) is not None:
            cfg[key] = getattr(args, key)
    if args.init:
        from dstenv.segment.checkpoint import network_checkpoint

        spec = network_checkpoint(args.init, "--init")["spec"]  # one-line errors
        # fine-tuning continues the checkpoint's network: a flag that says otherwise is a
        # mistake, not something to drop in silence
        given = {"--model": (args.model, spec["model"]),
                 "--inputs": (args.inputs, spec.get("inputs", "fcn10")),
                 "--model-kwargs": (args.model_kwargs or None, spec["model_kwargs"])}
        for flag, (mine, theirs) in given.items():
            if mine is not None and mine != theirs:
                raise CLIError(f"{flag} {mine}: --init {args.init} holds a network with "
                               f"{flag} {theirs}; leave {flag} out to continue it")
        cfg.update(init=str(args.init), model=spec["model"], model_kwargs=spec["model_kwargs"],
                   inputs=spec.get("inputs", "fcn10"))
    if args.stream is not None:
        if not args.steps_per_epoch:
            raise CLIError("--stream needs --steps-per-epoch (a stream has no end)")
        if args.class_weights is None and cfg.get("loss", "wce+lovasz").startswith("wce"):
            raise CLIError(
                "--stream with a weighted loss needs --class-weights (or --loss lovasz/ce)"
            )
        train_ds = StreamingDataset(args.stream or None, seed=args.seed, split="train",
                                    inputs=cfg["inputs"], labels=args.labels)
        val_ds = ShardDataset(args.data, split="val", inputs=cfg["inputs"],
                              labels=args.labels) if args.data else None
        cell = train_ds.config["grid"]["cell_size"]
        if val_ds is not None and val_ds.cell_size and abs(val_ds.cell_size - cell) > 1e-9:
            raise CLIError(f"--data {args.data}: its val split has cells of "
                           f"{val_ds.cell_size:g} m, the stream {cell:g} m; best.pt would be "
                           "chosen at another resolution: give data of the stream's cells")
        cfg["max_batches"] = args.steps_per_epoch
    else:
        if args.steps_per_epoch:
            raise CLIError("--steps-per-epoch goes with --stream (shards: an epoch is the "
                           "train split; --data with --stream validates on its val split)")
        if not args.data:
            raise CLIError("give --data DIR (shards from dstenv generate) or --stream SCENARIO")
        train_ds = ShardDataset(args.data, split="train", inputs=cfg["inputs"],
                                labels=args.labels)
        if len(train_ds) == 0:
            raise CLIError(f"{args.data}: no training frames (split 'train')")
        val_ds = ShardDataset(args.data, split="val", inputs=cfg["inputs"], labels=args.labels)
        val_ds = val_ds if len(val_ds) else None
    if args.class_weights is not None:
        cfg["class_weights"] = args.class_weights
    out = Path(args.out)
    try:
        with dataset_lock(out):  # one training per folder at a time
            _, history = train(cfg, train_ds, val_ds, out, resume=not args.no_resume,
                               progress=not args.quiet, data_id=training_data(train_ds),
                               log=(lambda m: None) if args.quiet else print)
    except DatasetLocked as exc:
        raise CLIError(f"--out {out}: another dstenv train writes into it ({exc})") from None
    best = max((m for m in history["val_miou"] if m is not None), default=None)
    print(
        f"checkpoints in {out} (last.pt, best.pt)"
        + (f"; best val mIoU {best:.3f}" if best is not None else "")
    )
    return 0


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

    _apart(args)
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
    print((out / "results.md").read_text())
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
    return 0 if ok or not args.check_goal else 1


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``dstenv train`` and ``dstenv benchmark`` to the CLI."""
    from dstenv.segment.presets import PRESETS
    from dstenv.segment.losses import LOSSES
    from dstenv.segment.models import MODELS

    p = sub.add_parser(
        "train",
        help="train a segmentation network on shards or a stream",
        description="Train a segmenter (Adam, median-frequency weighted CE and/or "
        "Lovasz-softmax). Checkpoints last.pt/best.pt are written "
        "atomically after every epoch; rerun to resume.",
    )
    p.add_argument("--data", metavar="DIR", help="dataset directory from dstenv generate "
                   "(with --stream: its val split validates)")
    p.add_argument("--stream", metavar="SCENARIO", nargs="?", const="",
                   help="train on frames simulated on the fly (no disk); optional scenario")
    p.add_argument("--steps-per-epoch", type=int, default=0,
                   help="batches per epoch when streaming")
    p.add_argument("--out", required=True, metavar="DIR", help="checkpoint directory")
    p.add_argument("--model", choices=sorted(MODELS), help="default unet-light (with --init: "
                   "the checkpoint's)")
    p.add_argument(
        "--model-kwargs",
        type=_json_arg,
        default={},
        metavar="JSON",
        help='builder options, e.g. \'{"base": 16}\' or \'{"vgg16_weights": "vgg16.pth"}\'',
    )
    p.add_argument("--loss", choices=LOSSES, default=None, help="default wce+lovasz")
    p.add_argument(
        "--class-weights",
        type=float,
        nargs=5,
        metavar="W",
        help="fixed class weights (default: median frequency of the training split)",
    )
    p.add_argument(
        "--weight-power",
        type=float,
        help="raise the median-frequency class weights to this power (default 1: paper eq. 2)",
    )
    p.add_argument("--inputs", choices=("fcn10", "fcn10+sensor", "fcn10+sensor+past"),
                   help="network input: BetP at t and t-1 (fcn10, the paper's), or also the "
                        "current sensor grid (fcn10+sensor), and the sensor grid of one "
                        "second earlier (fcn10+sensor+past); default fcn10 (with --init: "
                        "the checkpoint's)")
    p.add_argument("--labels", choices=("full", "kitti"), default="full",
                   help="label convention: as stored (full) or KITTI's (kitti: objects, "
                        "seen-free cells navigable, the rest ignored), for real drives")
    p.add_argument("--epochs", type=int, help="passes over the training split (default 10)")
    p.add_argument("--batch-size", type=int, help="grids per optimiser step (default 8)")
    p.add_argument("--lr", type=float, help="Adam learning rate (default 1e-3)")
    p.add_argument("--crop", type=int,
                   help="random square training crops [cells] (default 0: whole grids)")
    p.add_argument("--flip", type=float, help="probability of mirroring a training sample "
                                              "left-right (default 0: off)")
    p.add_argument("--num-workers", type=int, help="DataLoader workers (default 0: this process)")
    p.add_argument("--seed", type=int, default=0, help="seed of weights and batches (default 0)")
    p.add_argument("--device", default="auto", help="cpu, cuda or auto (default)")
    p.add_argument(
        "--init",
        metavar="CKPT",
        help="start from this checkpoint's weights (fine-tuning, e.g. a simulated-data model "
        "on a few labelled real frames); its model and builder options are used",
    )
    p.add_argument("--no-resume", action="store_true", help="start over even if last.pt exists")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=_train)

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
    b.add_argument("--quiet", action="store_true")
    b.set_defaults(func=_benchmark)
