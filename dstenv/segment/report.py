"""Benchmark outputs: a Markdown table, JSON, and PNG figures (the paper's Tables 2-3, Figs. 6-8).

Everything here reads the JSON-compatible ``results`` dict built by
:func:`dstenv.segment.benchmark.run_benchmark` (plus a few arrays for the
example grids), so a report can be redrawn from ``results.json`` alone.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from dstenv.dst.frame import CLASSES
from dstenv.dst.params import DSTParams
from dstenv.frame import IGNORE_INDEX
from dstenv.palette import CLASS_RGB, as_float, label_image
from dstenv.io import atomic_path, atomic_write_bytes
from dstenv.segment.replay import Episode, filter_episode

__all__ = [
    "write_report",
    "example_ids",
    "write_json",
    "markdown_table",
    "plot_confusions",
    "plot_curves",
    "plot_examples",
    "CLASS_COLORS",
]

#: RGB colour per class in ``CLASSES`` order, ``[0, 1]`` floats (:mod:`dstenv.palette`)
CLASS_COLORS = as_float(CLASS_RGB)


def write_json(path: str | Path, results: dict[str, Any]) -> Path:
    """Write ``results`` as indented JSON, atomically."""
    path = Path(path)
    atomic_write_bytes(path, (json.dumps(results, indent=2, allow_nan=False) + "\n").encode())
    return path


def _fmt(x: float | None) -> str:
    return "-" if x is None else f"{x:.3f}"


def markdown_table(results: dict[str, Any]) -> str:
    """The benchmark's tables: per-class IoU and mIoU, then accuracy/precision/recall.

    One block for all labelled cells and one for visible cells; one row per segmenter.
    """
    lines = [f"# Segmenter benchmark ({results.get('preset', 'custom')} preset)", ""]
    data = results.get("data", {})
    if data.get("evaluation_only"):
        lines += [
            f"Evaluation-only data ({data.get('source', '?')}): {data.get('test_frames', '?')} "
            f"test frames from {data.get('test_episodes', '?')} episode(s)/sequence(s), no train "
            f"split; grid {data.get('grid_shape', '?')} cells of {data.get('cell_size', '?')} m. "
            "DST from the stored BetP (or the filter re-run over the stored inputs), learned "
            "models from the given checkpoints.",
            "",
        ]
    elif data:
        lines += [
            f"Test split: {data.get('test_frames', '?')} frames from "
            f"{data.get('test_episodes', '?')} held-out map seeds (never used in training); "
            f"train {data.get('train_frames', '?')} frames, "
            f"val {data.get('val_frames', '?')}; grid {data.get('grid_shape', '?')} cells of "
            f"{data.get('cell_size', '?')} m.",
            "",
        ]
    for scope, title in (("all", "all labelled cells"), ("visible", "visible cells only")):
        lines += [
            f"## IoU over {title}",
            "",
            "| segmenter | " + " | ".join(CLASSES) + " | mIoU |",
            "|---|" + "---:|" * (len(CLASSES) + 1),
        ]
        for label, seg in results["segmenters"].items():
            m = seg[scope]
            lines.append(
                f"| {label} | "
                + " | ".join(_fmt(m["iou"][c]) for c in CLASSES)
                + f" | **{_fmt(m['miou'])}** |"
            )
        lines += [
            "",
            f"## Accuracy, precision, recall over {title} (precision/recall: class means)",
            "",
            "| segmenter | accuracy | precision | recall | "
            + " | ".join(f"P {c} | R {c}" for c in ("static", "moving"))
            + " |",
            "|---|---:|---:|---:|---:|---:|---:|---:|",
        ]
        for label, seg in results["segmenters"].items():
            m = seg[scope]
            lines.append(
                f"| {label} | {_fmt(m['accuracy'])} | {_fmt(m['mean_precision'])} | "
                f"{_fmt(m['mean_recall'])} | "
                + " | ".join(
                    f"{_fmt(m['precision'][c])} | {_fmt(m['recall'][c])}"
                    for c in ("static", "moving")
                )
                + " |"
            )
        lines.append("")
    if results.get("unscored"):
        lines += ["## Not scored", ""]
        lines += [f"- **{k}**: {why}" for k, why in results["unscored"].items()]
        lines.append("")
    goal = results.get("goal")
    if goal:
        met = {k: "met" if goal[f"{k}_met"] else "NOT met" for k in ("margin", "moving", "static")}
        lines += [
            "## Goal",
            "",
            f"Best learned: **{goal['best_learned']}** mIoU {_fmt(goal['best_learned_miou'])}; "
            f"best DST: **{goal['best_dst']}** mIoU {_fmt(goal['best_dst_miou'])}; "
            f"margin {_fmt(goal['margin'])} (goal >= 0.15: {met['margin']}); "
            f"moving IoU {_fmt(goal['moving_iou'])} (goal >= 0.6: {met['moving']}); "
            f"static IoU {_fmt(goal['static_iou'])} (goal >= 0.5: {met['static']}).",
            "",
        ]
    if results.get("command"):
        lines += ["Reproduce with:", "", "```", results["command"], "```", ""]
    return "\n".join(lines)


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
        ax.set_title(f"{label}\nmIoU {_fmt(seg[scope]['miou'])}", fontsize=8)
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
            ax.set_title(name, fontsize=7)
        row[-1].imshow(_colorize(ex["labels"]), interpolation="nearest")
        row[-1].set_title("ground truth", fontsize=7)
        for ax in row:
            ax.set_xticks([])
            ax.set_yticks([])
    handles = [plt.Rectangle((0, 0), 1, 1, color=CLASS_COLORS[k]) for k in range(len(CLASSES))]
    fig.legend(handles, CLASSES, loc="lower center", ncol=len(CLASSES), fontsize=7)
    return _save(fig, Path(path))


def example_ids(frames: list[dict[str, Any]], n: int) -> set[int]:
    """Frames with the most moving cells, one per episode (deterministic)."""
    order = sorted(range(len(frames)), key=lambda k: (-frames[k]["moving"], k))
    chosen, seeds = [], set()
    for k in order:
        if frames[k]["seed"] not in seeds:
            chosen.append(k)
            seeds.add(frames[k]["seed"])
        if len(chosen) >= n:
            break
    return set(chosen)


def write_report(
    results: dict[str, Any],
    out: Path,
    frames: list[dict[str, Any]],
    episodes: list[Episode] | None,
    preds: dict[str, dict[tuple[int, int], np.ndarray]],
    n_examples: int,
) -> None:
    """Write ``results.json``, ``results.md`` and ``figures/*.png`` into ``out``.

    Args:
        results: the benchmark results.
        out: output directory.
        frames: test frames (:func:`dstenv.segment.replay.split_index`).
        episodes: the replayed test episodes (for the DST BetP(moving) panel), or
            ``None`` to read the stored BetP and labels of the frames.
        preds: segmenter label -> ``{(seed, step): (H, W) prediction}`` of the examples.
        n_examples: example rows (frames chosen by :func:`example_ids`).
    """
    figs = out / "figures"
    write_json(out / "results.json", results)
    (out / "results.md").write_text(markdown_table(results))
    plot_confusions(results, figs / "confusion_all.png", "all")
    plot_confusions(results, figs / "confusion_visible.png", "visible")
    if results["histories"]:
        plot_curves(results["histories"], figs / "training_curves.png")
    examples = []
    if episodes is None:  # evaluation-only data: the stored BetP and labels
        from dstenv.data.shards import ShardReader

        for k in sorted(example_ids(frames, n_examples)):
            fr = frames[k]
            with ShardReader(fr["file"]) as r:
                d = r.get(fr["index"], ["pignistic", "labels"])
            key = (fr["seed"], fr["step"])
            examples.append(
                {
                    "title": f"episode {fr['seed']} step {fr['step']}",
                    "betp_moving": np.asarray(d["pignistic"][CLASSES.index("moving")]),
                    "predictions": {lab: p[key] for lab, p in preds.items() if key in p},
                    "labels": np.asarray(d["labels"]),
                }
            )
    by_seed = {ep.seed: ep for ep in episodes or []}
    for k in sorted(example_ids(frames, n_examples)) if episodes is not None else []:
        fr = frames[k]
        ep = by_seed[fr["seed"]]
        j = int(np.searchsorted(ep.steps, fr["step"]))
        gen = DSTParams.from_dict(results["data"]["generation_dst_params"])
        betp_m = filter_episode(
            Episode(
                ep.seed,
                ep.sensor,
                ep.gis,
                ep.poses,
                ep.steps[j : j + 1],
                ep.labels[j : j + 1],
                ep.visible[j : j + 1],
                ep.cell_size,
            ),
            gen,
        )[0, 4]
        examples.append(
            {
                "title": f"seed {fr['seed']} step {fr['step']}",
                "betp_moving": betp_m,
                "predictions": {
                    lab: p[(fr["seed"], fr["step"])]
                    for lab, p in preds.items()
                    if (fr["seed"], fr["step"]) in p
                },
                "labels": ep.labels[j],
            }
        )
    if examples:
        plot_examples(examples, figs / "examples.png")
