"""Scoring a segmenter on a dataset: confusion matrices over all and visible cells."""

from __future__ import annotations

from collections.abc import Iterable

import torch
from tqdm import tqdm

from dstenv.segment.metrics import ConfusionMeter
from dstenv.segment.segmenters import Segmenter

__all__ = ["evaluate", "batches"]


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
