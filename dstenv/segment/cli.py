"""``dstenv train``: fit a segmenter on shards or a stream (``dstenv benchmark``:
:mod:`dstenv.segment.bench_cli`)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

__all__ = ["check_out", "register"]


def _json_arg(text: str) -> dict[str, Any]:
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        raise argparse.ArgumentTypeError(f"not valid JSON: {exc.msg}") from None
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError("expected a JSON object, e.g. '{\"base\": 16}'")
    return value


def check_out(args: argparse.Namespace) -> None:
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
    from dstenv.io import made_folders, remove_made
    from dstenv.segment.train import default_train_config, train

    check_out(args)
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
    made = made_folders(out)
    try:
        with dataset_lock(out):  # one training per folder at a time
            _, history = train(cfg, train_ds, val_ds, out, resume=not args.no_resume,
                               progress=not args.quiet, data_id=training_data(train_ds),
                               log=(lambda m: None) if args.quiet else print)
    except DatasetLocked as exc:
        raise CLIError(f"--out {out}: another dstenv train writes into it ({exc})") from None
    except BaseException:
        remove_made(out, made)  # a run that failed before its first checkpoint leaves none
        raise
    best = max((m for m in history["val_miou"] if m is not None), default=None)
    print(
        f"checkpoints in {out} (last.pt, best.pt)"
        + (f"; best val mIoU {best:.3f}" if best is not None else "")
    )
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``dstenv train`` to the CLI."""
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
