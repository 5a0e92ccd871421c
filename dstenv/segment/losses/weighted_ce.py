"""Cross-entropy weighted by median frequency balancing (the paper's eq. 1-2).

Eq. 2 (after Eigen & Fergus): ``w_c = median_freq / freq(c)``, where ``freq(c)``
is the number of cells of class ``c`` divided by the number of cells in the
frames where ``c`` is present, and ``median_freq`` is the median of those
frequencies. Rare classes (static and moving obstacles: well under 1 % of cells)
get large weights, so the network cannot ignore them.

Eq. 1 averages the weighted negative log-likelihood over *all* labelled cells of
the batch (``sum w_y * -log p_y / n_cells``), not over the sum of weights as
``torch.nn.CrossEntropyLoss(weight=...)`` does; we follow the paper.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from dstenv.frame import IGNORE_INDEX

__all__ = ["class_statistics", "median_frequency_weights", "WeightedCrossEntropyLoss"]


def class_statistics(
    labels: Iterable[np.ndarray | torch.Tensor], num_classes: int, ignore_index: int = IGNORE_INDEX
) -> tuple[np.ndarray, np.ndarray]:
    """Per-class cell counts needed by :func:`median_frequency_weights`.

    Args:
        labels: label grids, each ``(H, W)`` or ``(B, H, W)`` integer; a batch axis
            counts as separate frames.
        num_classes: C.
        ignore_index: label value not counted anywhere.

    Returns:
        ``(counts, present_cells)``, each ``(C,) int64``: the number of cells of
        class c, and the number of labelled cells in the frames containing c.
    """
    counts = np.zeros(num_classes, dtype=np.int64)
    present = np.zeros(num_classes, dtype=np.int64)
    for lab in labels:
        arr = torch.as_tensor(lab).long()
        if arr.dim() == 2:
            arr = arr[None]
        for frame in arr:
            valid = frame[frame != ignore_index]
            if valid.numel() and (int(valid.min()) < 0 or int(valid.max()) >= num_classes):
                raise ValueError(f"label outside [0, {num_classes}) and not {ignore_index}")
            c = torch.bincount(valid, minlength=num_classes).numpy()
            counts += c
            present[c > 0] += int(valid.numel())
    return counts, present


def median_frequency_weights(
    counts: np.ndarray, present_cells: np.ndarray | None = None
) -> np.ndarray:
    """Class weights ``w_c = median(freq) / freq(c)`` (paper eq. 2).

    Args:
        counts: ``(C,)`` cells of each class in the training split.
        present_cells: ``(C,)`` cells of the frames containing each class (see
            :func:`class_statistics`); ``None`` uses the total cell count for every
            class (plain frequency, for data that only records class totals).

    Returns:
        ``(C,) float32``. A class absent from the training data gets weight 0 (its
        loss term never occurs) and is left out of the median.

    Raises:
        ValueError: if no class occurs at all, or the shapes differ.
    """
    counts = np.asarray(counts, dtype=np.float64)
    if present_cells is None:
        present_cells = np.full_like(counts, counts.sum())
    present_cells = np.asarray(present_cells, dtype=np.float64)
    if counts.shape != present_cells.shape or counts.ndim != 1:
        raise ValueError(
            f"counts {counts.shape} and present_cells {present_cells.shape} must be equal (C,)"
        )
    seen = counts > 0
    if not seen.any():
        raise ValueError("no labelled cell in the training data: cannot compute class weights")
    freq = np.zeros_like(counts)
    freq[seen] = counts[seen] / present_cells[seen]
    weights = np.zeros_like(counts)
    weights[seen] = np.median(freq[seen]) / freq[seen]
    return weights.astype(np.float32)


class WeightedCrossEntropyLoss(nn.Module):
    """Paper eq. 1: class-weighted cross-entropy averaged over labelled cells.

    Args:
        weights: ``(C,)`` class weights (e.g. :func:`median_frequency_weights`);
            ``None`` for the unweighted loss.
        ignore_index: label value that contributes nothing.

    Shapes: ``logits (B, C, H, W) float``, ``target (B, H, W) int64`` -> scalar.
    """

    def __init__(
        self, weights: np.ndarray | torch.Tensor | None = None, ignore_index: int = IGNORE_INDEX
    ):
        super().__init__()
        w = None if weights is None else torch.as_tensor(np.asarray(weights), dtype=torch.float32)
        self.register_buffer("weights", w)
        self.ignore_index = ignore_index

    def forward(self, logits: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        nll = F.cross_entropy(
            logits, target, weight=self.weights, ignore_index=self.ignore_index, reduction="sum"
        )
        n = (target != self.ignore_index).sum().clamp(min=1)
        return nll / n
