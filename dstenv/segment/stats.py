"""Confidence intervals: a cluster bootstrap over drives.

Frames of one drive are strongly correlated (the same parked cars, the same
street), so the unit of resampling is the drive's *map*: a resample draws as
many maps as were scored, with replacement, and takes every frame of each drawn
map (all its episodes). A metric is recomputed from the summed confusion
matrices (or object counts) of each resample; the 95 % interval is the 2.5th and
97.5th percentile (percentile bootstrap, :data:`N_RESAMPLES` resamples, fixed
seed, so reports are reproducible).

Paired differences (:func:`diff_ci`) resample the same maps for both segmenters,
which is what "the network beats DST" needs: both were scored on the same cells.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from dstenv.segment.metrics import summarize

__all__ = [
    "N_RESAMPLES",
    "resample_weights",
    "iou_batch",
    "miou_batch",
    "percentile_ci",
    "confusion_summary",
    "diff_ci",
    "object_summary",
]

#: bootstrap resamples per interval
N_RESAMPLES: int = 1000


def resample_weights(clusters: np.ndarray, n: int = N_RESAMPLES, seed: int = 0) -> np.ndarray:
    """How many times each drive enters each resample.

    Args:
        clusters: ``(E,) int`` cluster (map seed) of each drive.
        n: resamples.
        seed: RNG seed.

    Returns:
        ``(n, E) int64``: drive ``e`` counts as many times as its cluster was drawn.
    """
    uniq, inv = np.unique(np.asarray(clusters), return_inverse=True)
    rng = np.random.default_rng(seed)
    draws = rng.integers(0, len(uniq), size=(n, len(uniq)))
    counts = np.zeros((n, len(uniq)), dtype=np.int64)
    np.add.at(counts, (np.arange(n)[:, None], draws), 1)
    return counts[:, inv]


def iou_batch(cms: np.ndarray) -> np.ndarray:
    """IoU per class of ``(..., C, C)`` confusion matrices: ``(..., C)``, nan if absent."""
    cms = np.asarray(cms, dtype=np.float64)
    tp = np.diagonal(cms, axis1=-2, axis2=-1)
    rows, cols = cms.sum(-1), cms.sum(-2)
    den = rows + cols - tp
    with np.errstate(invalid="ignore", divide="ignore"):
        iou = np.where((rows > 0) & (den > 0), tp / np.where(den > 0, den, 1), np.nan)
    return iou


def miou_batch(cms: np.ndarray) -> np.ndarray:
    """mIoU over the classes present in the labels, per matrix: ``(...)``."""
    iou = iou_batch(cms)
    n = np.isfinite(iou).sum(-1)
    return np.where(n > 0, np.nansum(iou, -1) / np.maximum(n, 1), np.nan)


def percentile_ci(values: np.ndarray) -> list[float] | None:
    """``[lo, hi]`` 95 % percentile interval of finite ``values`` (``None`` if none)."""
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return None
    lo, hi = np.percentile(v, [2.5, 97.5])
    return [float(lo), float(hi)]


def confusion_summary(
    per_drive: np.ndarray, weights: np.ndarray, class_names: tuple[str, ...] | list[str]
) -> dict:
    """:func:`dstenv.segment.metrics.summarize` of the total, plus bootstrap intervals.

    Args:
        per_drive: ``(E, C, C) int64`` confusion matrix of each drive.
        weights: ``(n, E)`` :func:`resample_weights`.
        class_names: C names.

    Returns:
        The summary with ``"ci": {"miou": [lo, hi], "iou": {class: [lo, hi]}}``.
    """
    out = summarize(per_drive.sum(0), class_names)
    boot = np.tensordot(weights, per_drive, axes=1)  # (n, C, C)
    ious = iou_batch(boot)
    out["ci"] = {
        "miou": percentile_ci(miou_batch(boot)),
        "iou": {
            c: (percentile_ci(ious[:, k]) if out["iou"][c] is not None else None)
            for k, c in enumerate(class_names)
        },
    }
    return out


def diff_ci(
    a: np.ndarray,
    b: np.ndarray,
    weights: np.ndarray,
    metric: Callable[[np.ndarray], np.ndarray],
) -> tuple[float, list[float] | None]:
    """Paired difference ``metric(a) - metric(b)`` and its interval.

    Args:
        a, b: ``(E, ...)`` per-drive counts of two segmenters on the same drives.
        weights: ``(n, E)`` :func:`resample_weights`.
        metric: maps summed counts ``(..., *shape)`` to values ``(...)``, e.g.
            :func:`miou_batch` or ``lambda cm: iou_batch(cm)[..., k]``.

    Returns:
        ``(difference on all drives, [lo, hi])``.
    """
    point = float(metric(a.sum(0)) - metric(b.sum(0)))
    boot = metric(np.tensordot(weights, a, axes=1)) - metric(np.tensordot(weights, b, axes=1))
    return point, percentile_ci(boot)


def _ratio(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    num, den = np.asarray(num, np.float64), np.asarray(den, np.float64)
    return np.where(den > 0, num / np.where(den > 0, den, 1), np.nan)


def _num(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def object_summary(
    per_drive: np.ndarray,
    weights: np.ndarray,
    classes: tuple[str, ...],
    bands: tuple[float, ...],
) -> dict:
    """Object-level recall and precision per class and distance band, with intervals.

    Args:
        per_drive: ``(E, len(classes), len(bands) - 1, 4)``
            :func:`dstenv.segment.score.object_counts` sums per drive.
        weights: ``(n, E)`` :func:`resample_weights`.
        classes: object classes.
        bands: band edges [m].

    Returns:
        ``{class: {"objects", "predicted", "recall", "precision", "ci": {"recall",
        "precision"}, "bands": [{"range_m": [lo, hi], "objects", "predicted",
        "recall", "precision"}]}}``; ``None`` where undefined, ``hi`` ``None`` for
        the open last band.
    """
    total = per_drive.sum(0)
    boot = np.tensordot(weights, per_drive, axes=1)  # (n, classes, bands, 4)
    out = {}
    for c, name in enumerate(classes):
        t = total[c].sum(0)
        bt = boot[:, c].sum(1)
        out[name] = {
            "objects": int(t[0]),
            "predicted": int(t[2]),
            "recall": _num(_ratio(t[1], t[0])),
            "precision": _num(_ratio(t[3], t[2])),
            "ci": {
                "recall": percentile_ci(_ratio(bt[:, 1], bt[:, 0])),
                "precision": percentile_ci(_ratio(bt[:, 3], bt[:, 2])),
            },
            "bands": [
                {
                    "range_m": [bands[b], None if np.isinf(bands[b + 1]) else bands[b + 1]],
                    "objects": int(total[c, b, 0]),
                    "predicted": int(total[c, b, 2]),
                    "recall": _num(_ratio(total[c, b, 1], total[c, b, 0])),
                    "precision": _num(_ratio(total[c, b, 3], total[c, b, 2])),
                }
                for b in range(len(bands) - 1)
            ],
        }
    return out
