"""Lovasz-softmax: a convex surrogate of the multi-class IoU (Berman et al., CVPR 2018).

The paper's future work asks for a loss that optimises the metric itself; this is
it. For each class the cells' errors ``|1[y = c] - p_c|`` are sorted in decreasing
order and dotted with the gradient of the Lovasz extension of the Jaccard loss
(:func:`lovasz_grad`). Computed over the whole batch (one sorted list per class),
classes absent from the batch's labels are skipped (``classes="present"``).
"""

from __future__ import annotations

import torch
from torch import nn

from dstenv.frame import IGNORE_INDEX

__all__ = ["lovasz_grad", "lovasz_softmax", "LovaszSoftmaxLoss"]


def lovasz_grad(gt_sorted: torch.Tensor) -> torch.Tensor:
    """Gradient of the Lovasz extension w.r.t. sorted errors.

    Args:
        gt_sorted: ``(P,) float`` 0/1 ground truth sorted by decreasing error.

    Returns:
        ``(P,) float``: ``J(1..i) - J(1..i-1)`` where ``J(1..i)`` is the Jaccard loss
        when the ``i`` largest errors are mistakes.
    """
    gts = gt_sorted.sum()
    intersection = gts - gt_sorted.cumsum(0)
    union = gts + (1.0 - gt_sorted).cumsum(0)
    jaccard = 1.0 - intersection / union
    if gt_sorted.numel() > 1:
        jaccard[1:] = jaccard[1:] - jaccard[:-1]
    return jaccard


def lovasz_softmax(
    probs: torch.Tensor,
    target: torch.Tensor,
    classes: str = "present",
    ignore_index: int = IGNORE_INDEX,
) -> torch.Tensor:
    """Lovasz-softmax loss.

    Args:
        probs: ``(B, C, H, W) float`` class probabilities (softmax output).
        target: ``(B, H, W) int64`` labels or ``ignore_index``.
        classes: ``"present"`` (classes in ``target``) or ``"all"``.
        ignore_index: label value excluded.

    Returns:
        Scalar: mean over the considered classes of the class's Lovasz hinge;
        0 when no cell is labelled.
    """
    if classes not in ("present", "all"):
        raise ValueError(f"classes must be 'present' or 'all', got {classes!r}")
    c = probs.shape[1]
    flat = probs.permute(0, 2, 3, 1).reshape(-1, c)
    lab = target.reshape(-1)
    keep = lab != ignore_index
    flat, lab = flat[keep], lab[keep]
    if lab.numel() == 0:
        return probs.sum() * 0.0
    losses = []
    for k in range(c):
        fg = (lab == k).to(flat.dtype)
        if classes == "present" and fg.sum() == 0:
            continue
        errors = (fg - flat[:, k]).abs()
        errors_sorted, perm = torch.sort(errors, descending=True)
        losses.append(torch.dot(errors_sorted, lovasz_grad(fg[perm])))
    if not losses:
        return probs.sum() * 0.0
    return torch.stack(losses).mean()


class LovaszSoftmaxLoss(nn.Module):
    """:func:`lovasz_softmax` on logits: ``(B, C, H, W)`` logits, ``(B, H, W)`` target -> scalar."""

    def __init__(self, classes: str = "present", ignore_index: int = IGNORE_INDEX) -> None:
        super().__init__()
        self.classes = classes
        self.ignore_index = ignore_index

    def forward(self, logits: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        return lovasz_softmax(logits.softmax(1), target, self.classes, self.ignore_index)
