"""Segmentation metrics from a confusion matrix (the paper's Tables 2-3, Fig. 7).

Every metric here is a function of one ``(C, C) int64`` confusion matrix ``cm`` with
``cm[t, p]`` = number of cells whose true class is ``t`` and predicted class is
``p`` (rows: ground truth, columns: prediction, as in the paper's Fig. 7). Cells
labelled :data:`dstenv.frame.IGNORE_INDEX` never enter the matrix.

IoU and recall are defined only for classes present in the labels (``cm[t].sum() >
0``); a class absent from the labels has IoU ``nan`` (``None`` in summaries) even
when some segmenter predicts it, and mIoU is the mean over the classes present in
the labels. Every segmenter scored on the same cells therefore averages over the
same class set, and a class absent from a test split neither helps nor hurts.
"""

from __future__ import annotations

import numpy as np
import torch

from dstenv.frame import IGNORE_INDEX

__all__ = [
    "confusion_matrix",
    "iou_per_class",
    "mean_iou",
    "accuracy",
    "precision_per_class",
    "recall_per_class",
    "summarize",
    "ConfusionMeter",
]


def confusion_matrix(
    pred: torch.Tensor | np.ndarray,
    target: torch.Tensor | np.ndarray,
    num_classes: int,
    mask: torch.Tensor | np.ndarray | None = None,
    ignore_index: int = IGNORE_INDEX,
) -> np.ndarray:
    """Count (true, predicted) class pairs.

    Args:
        pred: ``(...)`` integer predicted classes in ``[0, num_classes)``.
        target: ``(...)`` integer true classes, same shape, or ``ignore_index``.
        num_classes: C.
        mask: optional ``(...) bool``; only cells where it is true are counted
            (e.g. the ``visible`` cells).
        ignore_index: label value excluded from the count.

    Returns:
        ``(C, C) int64`` with rows = true class, columns = predicted class.

    Raises:
        ValueError: on shape mismatch, or a class outside ``[0, C)`` that is not
            ``ignore_index`` (a silent wrong count otherwise).
    """
    p = torch.as_tensor(pred).reshape(-1).long()
    t = torch.as_tensor(target).reshape(-1).long()
    if p.shape != t.shape:
        raise ValueError(
            f"pred and target differ in size: {tuple(pred.shape)} vs {tuple(target.shape)}"
        )
    keep = t != ignore_index
    if mask is not None:
        m = torch.as_tensor(mask).reshape(-1)
        if m.shape != t.shape:
            raise ValueError(
                f"mask size {tuple(mask.shape)} does not match target {tuple(target.shape)}"
            )
        keep &= m.bool()
    p, t = p[keep], t[keep]
    for name, v in (("target", t), ("pred", p)):
        if v.numel() and (int(v.min()) < 0 or int(v.max()) >= num_classes):
            bad = int(v.max()) if int(v.max()) >= num_classes else int(v.min())
            raise ValueError(
                f"{name} holds class {bad} outside [0, {num_classes}) "
                f"and not the ignore index {ignore_index}"
            )
    counts = torch.bincount(t * num_classes + p, minlength=num_classes * num_classes)
    return counts.reshape(num_classes, num_classes).cpu().numpy().astype(np.int64)


def _safe_div(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    num = np.asarray(num, dtype=np.float64)
    den = np.asarray(den, dtype=np.float64)
    out = np.full(np.broadcast(num, den).shape, np.nan)
    np.divide(num, den, out=out, where=den > 0)
    return out


def iou_per_class(cm: np.ndarray) -> np.ndarray:
    """Intersection over union ``TP / (TP + FP + FN)`` per class: ``(C,) float64``.

    ``nan`` for a class absent from the labels (module docstring).
    """
    tp = np.diag(cm)
    iou = _safe_div(tp, cm.sum(0) + cm.sum(1) - tp)
    iou[cm.sum(1) == 0] = np.nan
    return iou


def mean_iou(cm: np.ndarray) -> float:
    """Mean of :func:`iou_per_class` over the classes present in the labels (nan if none)."""
    iou = iou_per_class(cm)
    return float(np.nanmean(iou)) if np.isfinite(iou).any() else float("nan")


def accuracy(cm: np.ndarray) -> float:
    """Fraction of counted cells classified correctly (nan for an empty matrix)."""
    total = cm.sum()
    return float(np.trace(cm) / total) if total else float("nan")


def precision_per_class(cm: np.ndarray) -> np.ndarray:
    """``TP / (TP + FP)`` per class (column sums): ``(C,) float64``."""
    return _safe_div(np.diag(cm), cm.sum(0))


def recall_per_class(cm: np.ndarray) -> np.ndarray:
    """``TP / (TP + FN)`` per class (row sums): ``(C,) float64``."""
    return _safe_div(np.diag(cm), cm.sum(1))


def _nanmean(v: np.ndarray) -> float:
    return float(np.nanmean(v)) if np.isfinite(v).any() else float("nan")


def summarize(cm: np.ndarray, class_names: tuple[str, ...] | list[str]) -> dict:
    """All metrics of one confusion matrix as JSON-compatible data.

    Returns:
        ``{"iou": {class: v}, "miou", "accuracy", "precision": {class: v},
        "recall": {class: v}, "mean_precision", "mean_recall", "cells",
        "confusion": [[int]]}``; undefined values are ``None``.
    """
    if cm.shape != (len(class_names), len(class_names)):
        raise ValueError(
            f"confusion matrix {cm.shape} does not match {len(class_names)} class names"
        )

    def per_class(v: np.ndarray) -> dict[str, float | None]:
        return {n: (None if np.isnan(x) else float(x)) for n, x in zip(class_names, v)}

    def scalar(x: float) -> float | None:
        return None if np.isnan(x) else float(x)

    prec, rec = precision_per_class(cm), recall_per_class(cm)
    return {
        "iou": per_class(iou_per_class(cm)),
        "miou": scalar(mean_iou(cm)),
        "accuracy": scalar(accuracy(cm)),
        "precision": per_class(prec),
        "recall": per_class(rec),
        "mean_precision": scalar(_nanmean(prec)),
        "mean_recall": scalar(_nanmean(rec)),
        "cells": int(cm.sum()),
        "confusion": cm.astype(int).tolist(),
    }


class ConfusionMeter:
    """Accumulates two confusion matrices: over all cells and over visible cells.

    Args:
        num_classes: C.
        ignore_index: label value never counted.
    """

    def __init__(self, num_classes: int, ignore_index: int = IGNORE_INDEX) -> None:
        self.num_classes = num_classes
        self.ignore_index = ignore_index
        self.all = np.zeros((num_classes, num_classes), dtype=np.int64)
        self.visible = np.zeros((num_classes, num_classes), dtype=np.int64)

    def update(
        self,
        pred: torch.Tensor,
        target: torch.Tensor,
        visible: torch.Tensor | None = None,
    ) -> None:
        """Add a batch: ``pred``/``target`` ``(B, H, W)`` int, ``visible`` ``(B, H, W) bool``."""
        self.all += confusion_matrix(pred, target, self.num_classes, None, self.ignore_index)
        if visible is not None:
            self.visible += confusion_matrix(
                pred, target, self.num_classes, visible, self.ignore_index
            )

    def summary(self, class_names: tuple[str, ...] | list[str]) -> dict:
        """``{"all": summarize(all), "visible": summarize(visible)}``."""
        return {
            "all": summarize(self.all, class_names),
            "visible": summarize(self.visible, class_names),
        }
