"""Networks on stored frames: loading checkpoints, quick confusion matrices.

:func:`load_checkpoints` loads trained networks checked against the data's input
channels (used by the benchmark); :func:`evaluate` scores one segmenter on
batches of a dataset (training scripts' quick check). Benchmark numbers come from
:func:`dstenv.segment.score.score` only.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path

import torch
from tqdm import tqdm

from dstenv.data.datasets import INPUT_CHANNELS
from dstenv.dst.frame import CLASSES
from dstenv.segment.metrics import ConfusionMeter
from dstenv.segment.segmenters import Segmenter, TorchSegmenter

__all__ = [
    "evaluate",
    "batches",
    "load_checkpoints",
]


def batches(dataset, batch_size: int = 8) -> Iterable[dict[str, torch.Tensor]]:
    """Sequential batches of a map-style dataset of ``{"x", "labels", "visible"}`` dicts."""
    return torch.utils.data.DataLoader(dataset, batch_size=batch_size, shuffle=False, num_workers=0)


def evaluate(
    segmenter: Segmenter,
    data: Iterable[dict[str, torch.Tensor]],
    num_classes: int = 5,
    progress: bool = False,
    desc: str | None = None,
) -> ConfusionMeter:
    """Confusion matrices of ``segmenter`` on batches.

    Args:
        segmenter: anything with ``predict(x (B, C, H, W)) -> (B, H, W) int64``.
        data: batches ``{"x": (B, C, H, W) float32, "labels": (B, H, W) int64,
            "visible": (B, H, W) bool}``.
        num_classes: C.
        progress: show a tqdm bar.

    Returns:
        A :class:`ConfusionMeter` holding the ``all`` and ``visible`` matrices.
    """
    meter = ConfusionMeter(num_classes)
    for batch in tqdm(
        data, desc=desc or f"eval {segmenter.label}", disable=not progress, leave=False
    ):
        pred = segmenter.predict(torch.as_tensor(batch["x"]))
        meter.update(pred, torch.as_tensor(batch["labels"]), torch.as_tensor(batch["visible"]))
    return meter


def load_checkpoints(
    paths: Sequence[str | Path],
    in_channels: int = 10,
    num_classes: int = len(CLASSES),
    device: str | torch.device = "cpu",
    taken: Sequence[str] = (),
) -> list[TorchSegmenter]:
    """Load trained networks to score on data with ``in_channels`` input channels.

    Labels are the model names, made unique with the checkpoint path when two
    checkpoints hold the same model or the name is in ``taken``; the path is also
    in the attribute ``checkpoint``.

    Raises:
        FileNotFoundError, ValueError: a missing or unreadable checkpoint, or one whose
            input channels or classes do not match the data (one line naming the file).
    """
    from dstenv.segment.checkpoint import load_segmenter

    segs = []
    for path in paths:
        seg = load_segmenter(path, device)
        # fcn10+sensor(+past) networks read the frames' sensor grids besides the BetP
        from_data = seg.in_channels - (INPUT_CHANNELS[seg.inputs] - 10
                                       if seg.inputs.startswith("fcn10+") else 0)
        if from_data != in_channels:
            raise ValueError(
                f"{path}: checkpoint takes {seg.in_channels} input channels"
                + (f" ({seg.inputs})" if seg.inputs != "fcn10" else "")
                + f" but the data gives {in_channels} (BetP at t and t-1)"
            )
        if seg.num_classes != num_classes:
            raise ValueError(
                f"{path}: checkpoint predicts {seg.num_classes} classes, the data has {num_classes}"
            )
        seg.checkpoint = str(path)
        segs.append(seg)
    names = [s.label for s in segs] + list(taken)
    for seg in segs:
        if names.count(seg.label) > 1:
            seg.label = f"{seg.label} ({seg.checkpoint})"
    return segs
