"""The benchmark's PNG figures (the paper's Figs. 6-8): confusion matrices, training
curves, example grids and the training-set-size curve, drawn from the JSON-compatible
``results`` dict (:mod:`dstenv.segment.report`) and example grids; matplotlib is
imported only when a figure is drawn (Agg backend).
"""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Any

import numpy as np

from dstenv.dst.frame import CLASSES
from dstenv.frame import IGNORE_INDEX
from dstenv.io import atomic_path
from dstenv.palette import CLASS_RGB, as_float, label_image

__all__ = [
    "CLASS_COLORS",
    "plot_confusions",
    "plot_curves",
    "plot_examples",
    "plot_size_curve",
    "score_text",
]

#: RGB colour per class in ``CLASSES`` order, ``[0, 1]`` floats (:mod:`dstenv.palette`)
CLASS_COLORS = as_float(CLASS_RGB)


def score_text(x: float | None) -> str:
    """A score as the report's tables and the figures print it: 3 decimals, "-" if none."""
    return "-" if x is None else f"{x:.3f}"


#: [characters] a row label longer than this is wrapped in a panel title (the KITTI
#: rows' "unet-light kitti-labels (seed 0) (sim only)" ran into the next panel's)
TITLE_WIDTH = 26


def _title(label: str) -> str:
    """``label`` as a panel title: unchanged up to :data:`TITLE_WIDTH` characters, else
    wrapped onto lines of at most that many."""
    return label if len(label) <= TITLE_WIDTH else "\n".join(textwrap.wrap(label, TITLE_WIDTH))


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig: Any, path: Path) -> Path:
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=110, bbox_inches="tight", format=path.suffix.lstrip("."))
    finally:
        _plt().close(fig)
    return path


def plot_confusions(results: dict[str, Any], path: str | Path, scope: str = "all") -> Path:
    """Row-normalised confusion matrices (true rows, predicted columns), one panel per segmenter."""
    plt = _plt()
    segs = results["segmenters"]
    n = len(segs)
    fig, axes = plt.subplots(1, n, figsize=(3.4 * n, 3.4), squeeze=False)
    short = [c.replace("_", "-") for c in CLASSES]  # whole names: "stati" reads as nothing
    for ax, (label, seg) in zip(axes[0], segs.items()):
        cm = np.asarray(seg[scope]["confusion"], dtype=np.float64)
        rows = cm.sum(1, keepdims=True)
        norm = np.divide(cm, rows, out=np.zeros_like(cm), where=rows > 0)
        ax.imshow(norm, vmin=0, vmax=1, cmap="Blues")
        for i in range(len(CLASSES)):
            for j in range(len(CLASSES)):
                ax.text(
                    j,
                    i,
                    f"{norm[i, j]:.2f}",
                    ha="center",
                    va="center",
                    fontsize=7,
                    color="white" if norm[i, j] > 0.6 else "black",
                )
        ax.set_xticks(range(len(CLASSES)), short, rotation=45, ha="right", fontsize=7)
        ax.set_yticks(range(len(CLASSES)), short, fontsize=7)
        miou = seg[scope]["miou"]
        ax.set_title(f"{_title(label)}\nmIoU {score_text(miou)}", fontsize=8)
        ax.set_xlabel("predicted", fontsize=7)
    axes[0][0].set_ylabel("true", fontsize=7)
    fig.suptitle(f"confusion matrices ({scope} cells)", fontsize=9)
    return _save(fig, Path(path))


def plot_curves(histories: dict[str, dict[str, list]], path: str | Path) -> Path:
    """Training and validation loss, and validation mIoU, per epoch (the paper's Fig. 6)."""
    plt = _plt()
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(9, 3.4))
    for name, h in histories.items():
        ax1.plot(h["epoch"], h["train_loss"], "-o", ms=3, label=f"{name} train")
        if any(v is not None for v in h["val_loss"]):
            ax1.plot(
                h["epoch"],
                [np.nan if v is None else v for v in h["val_loss"]],
                "--o",
                ms=3,
                label=f"{name} val",
            )
            ax2.plot(
                h["epoch"],
                [np.nan if v is None else v for v in h["val_miou"]],
                "-o",
                ms=3,
                label=name,
            )
    ax1.set_xlabel("epoch")
    ax1.set_ylabel("loss")
    ax1.legend(fontsize=7)
    ax2.set_xlabel("epoch")
    ax2.set_ylabel("validation mIoU")
    ax2.legend(fontsize=7)
    return _save(fig, Path(path))


def _colorize(labels: np.ndarray) -> np.ndarray:
    return as_float(label_image(np.asarray(labels), IGNORE_INDEX))


def plot_examples(examples: list[dict[str, Any]], path: str | Path) -> Path:
    """Example grids (the paper's Fig. 8): DST BetP(moving), predictions, ground truth.

    Args:
        examples: each ``{"title": str, "betp_moving": (H, W) float, "predictions":
            {label: (H, W) int}, "labels": (H, W) int}``.
    """
    plt = _plt()
    if not examples:
        raise ValueError("no examples to plot")
    names = list(examples[0]["predictions"])
    ncol = 2 + len(names)
    fig, axes = plt.subplots(
        len(examples), ncol, figsize=(2.3 * ncol, 2.4 * len(examples)), squeeze=False
    )
    for row, ex in zip(axes, examples):
        row[0].imshow(ex["betp_moving"], vmin=0, vmax=1, cmap="magma")
        row[0].set_title(f"DST BetP(moving)\n{ex['title']}", fontsize=7)
        for ax, name in zip(row[1:], names):
            ax.imshow(_colorize(ex["predictions"][name]), interpolation="nearest")
            ax.set_title(_title(name), fontsize=7)
        row[-1].imshow(_colorize(ex["labels"]), interpolation="nearest")
        row[-1].set_title("ground truth", fontsize=7)
        for ax in row:
            ax.set_xticks([])
            ax.set_yticks([])
    handles = [plt.Rectangle((0, 0), 1, 1, color=CLASS_COLORS[k]) for k in range(len(CLASSES))]
    fig.legend(handles, CLASSES, loc="lower center", ncol=len(CLASSES), fontsize=7)
    return _save(fig, Path(path))


def plot_size_curve(results: dict[str, Any], path: str | Path) -> Path:
    """Observed-cell IoU (moving, static, mIoU with 95 % CI) against training frames."""
    plt = _plt()
    rows = results["curve"]
    n = [r["train_frames"] for r in rows]
    fig, ax = plt.subplots(figsize=(5, 3.4))
    for key, style in (("miou", "-o"), ("moving", "--s"), ("static", "--^")):
        vals = [r["observed"]["miou"] if key == "miou" else r["observed"]["iou"][key]
                for r in rows]
        ax.plot(n, [np.nan if v is None else v for v in vals], style, ms=4,
                label="mIoU" if key == "miou" else f"IoU {key}")
    lo = [r["observed"]["ci"]["miou"][0] if r["observed"]["ci"]["miou"] else np.nan for r in rows]
    hi = [r["observed"]["ci"]["miou"][1] if r["observed"]["ci"]["miou"] else np.nan for r in rows]
    ax.fill_between(n, lo, hi, alpha=0.2)
    ax.set_xscale("log")
    ax.set_xlabel("training frames")
    ax.set_ylabel("observed-cell IoU")
    ax.legend(fontsize=7)
    return _save(fig, Path(path))
