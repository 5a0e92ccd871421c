"""FCN-DST on simulated perception grids, in one readable file (cleanrl style).

What it does, top to bottom:

1. generate train/val/test shards (disjoint map seeds) with ``dstenv.data``;
2. train a network on BetP at t and t-1 (the paper's 10 channels) with Adam and
   median-frequency weighted cross-entropy + Lovasz-softmax;
3. score it and the pure-DST baseline (argmax BetP, generation parameters) on the
   test split, over all cells and over visible cells.

``dstenv benchmark`` does the same for every segmenter (DST presets, tuned DST,
several networks) and writes figures; this script is the short version to read
and modify. Run::

    python baselines/segmentation/fcn_dst.py --frames 400 --epochs 4 --grid 64
"""

from __future__ import annotations

import argparse
import dataclasses
from dataclasses import dataclass
from pathlib import Path

from dstenv.data import ShardDataset
from dstenv.data.generate import GenerateSpec, generate
from dstenv.data.sampling import scenario_config
from dstenv.dst import CLASSES
from dstenv.segment import create_segmenter, load_segmenter
from dstenv.segment.evaluate import batches, evaluate
from dstenv.segment.train import train


@dataclass
class Args:
    out: str = "runs/fcn_dst"  # output directory (data, checkpoints)
    scenario: str = ""  # scenario name or .toml; "" = defaults
    frames: int = 400  # total frames, 80/10/10 train/val/test
    grid: int = 64  # [cells] square grid side
    episode_length: int = 100  # [steps] of 0.1 s
    stride: int = 5  # keep a frame every `stride` steps
    model: str = "unet-light"  # dstenv.segment.models.MODELS key
    epochs: int = 4
    batch_size: int = 8
    lr: float = 2e-3
    loss: str = "wce+lovasz"
    seed: int = 0
    device: str = "auto"


def main(args: Args) -> dict[str, float]:
    out = Path(args.out)
    config = scenario_config(
        args.scenario or None, {"grid": {"height": args.grid, "width": args.grid}}
    )
    spec = GenerateSpec(
        config=config,
        frames=args.frames,
        seed=args.seed,
        episode_length=args.episode_length,
        stride=args.stride,
        warmup=args.stride,
    )
    generate(spec, out / "data")

    train_ds = ShardDataset(out / "data", split="train")
    val_ds = ShardDataset(out / "data", split="val")
    test_ds = ShardDataset(out / "data", split="test")
    train(
        {
            "model": args.model,
            "epochs": args.epochs,
            "batch_size": args.batch_size,
            "lr": args.lr,
            "loss": args.loss,
            "seed": args.seed,
            "device": args.device,
        },
        train_ds,
        val_ds,
        out / "model",
    )

    scores = {}
    for seg in (create_segmenter("dst"), load_segmenter(out / "model" / "best.pt")):
        meter = evaluate(seg, batches(test_ds, args.batch_size))
        summary = meter.summary(CLASSES)
        scores[seg.label] = summary["all"]["miou"]
        ious = " ".join(f"{c} {summary['all']['iou'][c] or 0:.3f}" for c in CLASSES)
        print(
            f"{seg.label:16s} mIoU {summary['all']['miou']:.3f} | visible mIoU "
            f"{summary['visible']['miou']:.3f} | {ious}"
        )
    return scores


if __name__ == "__main__":
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    for f in dataclasses.fields(Args):
        parser.add_argument(
            f"--{f.name.replace('_', '-')}", type=type(f.default), default=f.default
        )
    main(Args(**vars(parser.parse_args())))
