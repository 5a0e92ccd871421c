"""Segmentation losses, one concept per file, created by name with :func:`build_loss`."""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from dstenv.frame import IGNORE_INDEX
from dstenv.segment.losses.lovasz import LovaszSoftmaxLoss, lovasz_softmax
from dstenv.segment.losses.weighted_ce import (
    WeightedCrossEntropyLoss,
    class_statistics,
    median_frequency_weights,
)

__all__ = [
    "LOSSES",
    "build_loss",
    "CombinedLoss",
    "LovaszSoftmaxLoss",
    "lovasz_softmax",
    "WeightedCrossEntropyLoss",
    "class_statistics",
    "median_frequency_weights",
]

#: loss names accepted by :func:`build_loss` and ``dstenv train --loss``
LOSSES: tuple[str, ...] = ("wce", "ce", "lovasz", "wce+lovasz")


class CombinedLoss(nn.Module):
    """Sum of losses: ``(B, C, H, W)`` logits, ``(B, H, W)`` target -> scalar."""

    def __init__(self, *losses: nn.Module) -> None:
        super().__init__()
        self.losses = nn.ModuleList(losses)

    def forward(self, logits: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        return sum(loss(logits, target) for loss in self.losses)


def build_loss(
    name: str, weights: np.ndarray | None = None, ignore_index: int = IGNORE_INDEX
) -> nn.Module:
    """Create a loss by name.

    Args:
        name: one of :data:`LOSSES`: ``"wce"`` (median-frequency weighted CE, needs
            ``weights``), ``"ce"`` (unweighted), ``"lovasz"``, ``"wce+lovasz"``.
        weights: ``(C,)`` class weights for the weighted variants.
        ignore_index: label value excluded.
    """
    if name not in LOSSES:
        raise ValueError(f"unknown loss {name!r}; choose from {', '.join(LOSSES)}")
    if name.startswith("wce") and weights is None:
        raise ValueError(
            f"loss {name!r} needs class weights (median frequency of the training split)"
        )
    if name == "ce":
        return WeightedCrossEntropyLoss(None, ignore_index)
    if name == "lovasz":
        return LovaszSoftmaxLoss(ignore_index=ignore_index)
    wce = WeightedCrossEntropyLoss(weights, ignore_index)
    return wce if name == "wce" else CombinedLoss(wce, LovaszSoftmaxLoss(ignore_index=ignore_index))
