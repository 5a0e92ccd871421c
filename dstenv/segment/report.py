"""Benchmark outputs: a Markdown table, JSON, and the figures of :mod:`dstenv.segment.figures`
(the paper's Tables 2-3, Figs. 6-8).

Everything here reads the JSON-compatible ``results`` dict built by
:func:`dstenv.segment.benchmark.run_benchmark` (schema: ``docs/benchmark.md``),
plus the example grids, so the tables can be redrawn from ``results.json`` alone
(``markdown_table(json.load(...))``).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from dstenv.dst.frame import CLASSES
from dstenv.dst.params import DSTParams
from dstenv.io import atomic_write_bytes, atomic_write_text
from dstenv.segment.figures import (
    plot_confusions,
    plot_curves,
    plot_examples,
    plot_size_curve,
    score_text,
)
from dstenv.segment.replay import Episode, filter_episode

__all__ = [
    "write_report",
    "example_keys",
    "write_json",
    "markdown_table",
]


def write_json(path: str | Path, results: dict[str, Any]) -> Path:
    """Write ``results`` as indented JSON, atomically."""
    path = Path(path)
    atomic_write_bytes(path, (json.dumps(results, indent=2, allow_nan=False) + "\n").encode())
    return path


def _ci(x: float | None, ci: list[float] | None) -> str:
    if x is None or ci is None:
        return score_text(x)
    return f"{score_text(x)} [{score_text(ci[0])}, {score_text(ci[1])}]"


_SCOPE_TITLES = {
    "observed": "IoU over observed cells (headline: cells observed so far in the drive)",
    "visible": "IoU over visible cells (observed in the current sweep)",
    "all": "IoU over all labelled cells (amodal: includes never-observed cells, "
    "i.e. shape completion)",
}


def _iou_table(segs: dict[str, Any], scope: str) -> list[str]:
    lines = [
        f"## {_SCOPE_TITLES[scope]}",
        "",
        "| segmenter | kind | " + " | ".join(CLASSES) + " | mIoU [95 % CI] |",
        "|---|---|" + "---:|" * (len(CLASSES) + 1),
    ]
    for label, seg in segs.items():
        m = seg[scope]
        cis = m.get("ci", {}).get("iou", {})
        cells = []
        for c in CLASSES:
            cells.append(_ci(m["iou"][c], cis.get(c)) if c in ("static", "moving")
                         else score_text(m["iou"][c]))
        lines.append(
            f"| {label} | {seg['kind']} | " + " | ".join(cells)
            + f" | **{_ci(m['miou'], m.get('ci', {}).get('miou'))}** |"
        )
    return lines + [""]


def _object_table(segs: dict[str, Any]) -> list[str]:
    first = next(iter(segs.values()), {}).get("objects")
    if not first:
        return []
    bands = first["static"]["bands"]
    names = [f"{b['range_m'][0]:g}-{b['range_m'][1]:g} m" if b["range_m"][1] is not None
             else f">= {b['range_m'][0]:g} m" for b in bands]
    lines = [
        "## Objects (observed cells): recall / precision of static and moving objects",
        "",
        "An object is a connected component of static (moving) labels with an observed "
        "cell; recovered when most of its observed static-or-moving predictions have its "
        "class. Overall values with 95 % CI, then recall by distance to the ego.",
        "",
        "| segmenter | R static | P static | R moving | P moving | "
        + " | ".join(f"R static {n} | R moving {n}" for n in names) + " |",
        "|---|" + "---:|" * (4 + 2 * len(names)),
    ]
    for label, seg in segs.items():
        o = seg["objects"]
        row = [_ci(o[c][k], o[c]["ci"][k]) for c in ("static", "moving")
               for k in ("recall", "precision")]
        for b in range(len(names)):
            row += [score_text(o[c]["bands"][b]["recall"]) for c in ("static", "moving")]
        lines.append(f"| {label} | " + " | ".join(row) + " |")
    counts = {c: first[c]["objects"] for c in ("static", "moving")}
    lines += ["", f"Objects with an observed cell: static {counts['static']}, "
              f"moving {counts['moving']}.", ""]
    return lines


def _prf_table(segs: dict[str, Any], scope: str) -> list[str]:
    lines = [
        f"## Accuracy, precision, recall over {scope} cells (precision/recall: class means)",
        "",
        "| segmenter | accuracy | precision | recall | "
        + " | ".join(f"P {c} | R {c}" for c in ("static", "moving")) + " |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for label, seg in segs.items():
        m = seg[scope]
        lines.append(
            f"| {label} | {score_text(m['accuracy'])} | {score_text(m['mean_precision'])} | "
            f"{score_text(m['mean_recall'])} | "
            + " | ".join(f"{score_text(m['precision'][c])} | {score_text(m['recall'][c])}"
                         for c in ("static", "moving")) + " |"
        )
    return lines + [""]


def _goal_lines(goal: dict[str, Any] | None, real: dict[str, Any] | None) -> list[str]:
    lines = []
    if goal:
        def met(ok: bool) -> str:
            return "met" if ok else "NOT met"

        lines += [
            "## Goal (simulated test maps, observed cells)",
            "",
            f"Best network **{goal['best_learned']}** mIoU "
            f"{score_text(goal['best_learned_miou'])} vs best non-learned "
            f"**{goal['best_baseline']}** {score_text(goal['best_baseline_miou'])}: "
            f"margin {_ci(goal['margin'], goal['margin_ci'])} (goal >= "
            f"{goal['margin_goal']:.2f} with the interval above 0: {met(goal['margin_met'])}); "
            f"moving IoU difference {_ci(goal['moving_diff'], goal['moving_diff_ci'])} "
            f"({met(goal['moving_met'])}); static IoU difference "
            f"{_ci(goal['static_diff'], goal['static_diff_ci'])} ({met(goal['static_met'])}).",
            "",
        ]
    if real:
        lines += ["## Goal (real data): networks vs pure DST, "
                  f"{real['scope']} cells, reference {real['reference']}", ""]
        for label, row in real["networks"].items():
            lines.append(
                f"- **{label}**: moving {_ci(row['moving']['diff'], row['moving']['ci'])}, "
                f"static {_ci(row['static']['diff'], row['static']['ci'])} "
                f"(goal >= {row.get('margin', real['margin_goal']):.2f}: "
                + ("met" if row["moving"]["met"] and row["static"]["met"] else "NOT met") + ")"
            )
        strongest = real.get("strongest") or {}
        if strongest:
            lines += ["", "Against the strongest non-learned row of each class (not the goal): "
                      + "; ".join(f"{name} **{b['baseline']}** {score_text(b['iou'])}"
                                  for name, b in strongest.items()), ""]
            for label, row in real["networks"].items():
                vs = {name: row[name]["vs_strongest"] for name in strongest
                      if "vs_strongest" in row[name]}
                diffs = [f"{name} {_ci(d['diff'], d['ci'])}" for name, d in vs.items()]
                lines.append(f"- **{label}**: " + ", ".join(diffs))
        lines.append("")
    return lines


def _real_lines(results: dict[str, Any]) -> list[str]:
    """What ``--kitti --finetune-frames N`` learned from the real frames it did not score."""
    real = results.get("real") or {}
    start = real.get("finetune_start")
    net = real.get("real_net")
    lines = []
    if net:
        f = net["frames"]
        lines += [f"{', '.join(f'`{k} (sim only)`' for k in net['checkpoints'])}: trained on "
                  f"{f['train']} simulated frames ({f['val']} validation) at this data's grid "
                  f"({net['grid'][0]} x {net['grid'][1]} cells of {net['cell_size']:g} m"
                  f"{', every drive without a map, as the real ones' if net.get('no_map') else ''}"
                  "), "
                  "labelled as KITTI labels (objects, seen-free cells navigable, the rest "
                  "ignored), reading the sensor grid besides BetP t / t-1; no real frame.", ""]
        made = {k: v for k, v in net.get("decided", {}).items() if "checkpoint" in v}
        if made:
            lines[-2] += (" Rows `..., calibrated + free` decide with a static/moving offset "
                          "chosen on the simulated validation drives (offsets: "
                          + ", ".join(f"{k} {v['moving_offset']:+g}" for k, v in made.items())
                          + "), then the free-space rule"
                          + ("; an ensemble averages its seeds' logits before deciding."
                             if any("members" in v for v in made.values()) else "."))
    if not real.get("finetune_frames") or not start:
        return lines
    n = real["finetune_frames"]
    cands = ", ".join(f"{k} {v:.3f}" for k, v in start["start_miou"].items())
    lines += [f"Frames 0-{n - 1} of each sequence are labelled training frames, scored by no "
             f"row (every row is scored from step {real.get('scored_from_step')} on): the "
             f"fine-tuning starts from {start['start']}, the simulated network with the best "
             f"mIoU on them ({cands})."]
    ep = start.get("epochs")  # runs before 2026-12-05: 5 epochs, no choice
    if ep and len(ep["candidates"]) > 1:
        tried = ", ".join(f"{e} {v:.3f}" for e, v in ep["miou"].items())
        lines[-1] += (f" Its length, {ep['chosen']} epochs, was chosen on {ep['chosen_on']}, "
                      f"which nothing trains on and no row scores (mIoU by epochs: {tried}).")
    from dstenv.segment.real import REAL_TUNED

    tuned = results.get("segmenters", {}).get(REAL_TUNED)
    if tuned is not None:
        t = tuned["describe"]["tuning"]
        lines[-1] += (f" `{REAL_TUNED}` searched the DST parameters on "
                     f"the fine-tuning frames ({t['budget']} sets, {t['scope']} cells: mIoU "
                     f"{t['start_miou']:.3f} with the defaults, {t['best_miou']:.3f} tuned).")
    return lines + [""]


def markdown_table(results: dict[str, Any]) -> str:
    """The report: headline (observed) table, objects, visible, amodal, goal.

    One row per segmenter; 95 % intervals are a bootstrap over maps
    (:mod:`dstenv.segment.stats`).
    """
    data = results.get("data", {})
    if data.get("evaluation_only"):
        src = data.get("source", "?")
        lines = [f"# Segmenter benchmark on {src} data", "",
                 f"Evaluation-only data ({src}): {data.get('test_frames', '?')} "
                 f"frames from {data.get('test_episodes', '?')} drive(s), no train split; grid "
                 f"{data.get('grid_shape', '?')} cells of {data.get('cell_size', '?')} m. DST "
                 "from the stored BetP (or the filter re-run over the stored inputs), networks "
                 "from the given checkpoints.", ""]
        lines += _real_lines(results)
    else:
        lines = [f"# Segmenter benchmark ({results.get('preset') or 'custom'} preset)", ""]
        if data:
            lines += [
                f"Test split: {data.get('test_frames', '?')} frames of "
                f"{data.get('test_episodes', '?')} drive(s) on {data.get('test_maps', '?')} "
                f"held-out map(s) (never used in training, tuning or model selection); train "
                f"{data.get('train_frames', '?')} frames, val {data.get('val_frames', '?')}; "
                f"grid {data.get('grid_shape', '?')} cells of {data.get('cell_size', '?')} m; "
                f"DST fused every {data.get('filter_period', 1)} step(s).", ""]
    if data.get("observed_definition") == "visible":
        lines += ["Observed cells = visible cells here: the stored frames do not hold the "
                  "filter history needed to accumulate earlier sweeps.", ""]
    segs = results["segmenters"]
    lines += _iou_table(segs, "observed")
    lines += _object_table(segs)
    lines += _prf_table(segs, "observed")
    lines += _iou_table(segs, "visible")
    lines += _iou_table(segs, "all")
    seeded = {k: v["seeds"] for k, v in segs.items() if "seeds" in v}
    if seeded:
        lines += ["## Training seeds (observed mIoU per seed, mean, t-interval)", ""]
        for k, sd in seeded.items():
            o = sd["observed"]
            lines.append(f"- **{k}**: " + ", ".join(score_text(v) for v in o["miou"])
                         + f"; mean {_ci(o['miou_mean'], o['miou_ci'])}")
        lines.append("")
    if results.get("curve"):
        lines += ["## Training-set size (observed cells)", "",
                  "| train frames | mIoU [95 % CI] | static | moving |", "|---:|---:|---:|---:|"]
        for row in results["curve"]:
            o = row["observed"]
            lines.append(f"| {row['train_frames']} | {_ci(o['miou'], o['ci']['miou'])} | "
                         f"{score_text(o['iou']['static'])} | {score_text(o['iou']['moving'])} |")
        lines.append("")
    search = results.get("search")
    if search:
        vals = ", ".join(f"{r['value']}: {r['val_miou']:.3f}" for r in search["evaluations"])
        lines += [f"Chosen on {search['validation_drives']} validation drives ({search['scope']} "
                  f"mIoU of {search['model']}): {search['key']} = {search['chosen']} ({vals}); "
                  "the search is in search.json.", ""]
    ties = data.get("no_map_ties")
    if ties and ties.get("tied_cells"):
        lines += [f"BetP(building) = BetP(static) is the largest BetP in {ties['tied_cells']} "
                  f"of {ties['labelled_cells']} labelled cells ({100 * ties['share']:.1f} %): "
                  "without a map the two classes get the same mass; argmax gives the tie to "
                  "building, so DST never predicts static there.", ""]
    if results.get("unscored"):
        lines += ["## Not scored", ""]
        lines += [f"- **{k}**: {why}" for k, why in results["unscored"].items()]
        lines.append("")
    if results.get("notes"):
        lines += ["## Notes", "", *[f"- {n}" for n in results["notes"]], ""]
    lines += _goal_lines(results.get("goal"), results.get("real_goal"))
    if results.get("command"):
        lines += [f"Reproduce with (run of {results.get('date', '?')}):", "", "```",
                  results["command"], "```", ""]
    return "\n".join(lines)


def example_keys(episodes: list[Episode], n: int) -> list[tuple[int, int, int]]:
    """Frame keys ``(seed, episode, step)`` with the most moving cells, one per drive."""
    moving = CLASSES.index("moving")
    cands = []
    for ep in episodes:
        counts = (ep.labels == moving).reshape(len(ep.steps), -1).sum(1)
        if len(counts):
            k = int(np.argmax(counts))
            cands.append((-int(counts[k]), ep.frame_key(k)))
    return [key for _, key in sorted(cands)[:n]]


def write_report(
    results: dict[str, Any],
    out: Path,
    episodes: list[Episode],
    generation_params: DSTParams,
    preds: dict[str, dict[tuple[int, int, int], np.ndarray]],
) -> None:
    """Write ``results.json``, ``results.md`` and ``figures/*.png`` into ``out``.

    Args:
        results: the benchmark results.
        out: output directory.
        episodes: the scored drives (for the example grids).
        generation_params: DST parameters of the stored BetP (the BetP(moving) panel).
        preds: segmenter label -> ``{(seed, episode, step): (H, W) prediction}``.
    """
    figs = out / "figures"
    # the figures first, results.json last: a report cut short (a full disk) is never one
    # that looks finished without its figures (a rerun writes it whole)
    for name in ("results.json", "results.md"):
        (out / name).unlink(missing_ok=True)
    for scope in ("observed", "visible", "all"):
        plot_confusions(results, figs / f"confusion_{scope}.png", scope)
    if results["histories"]:
        plot_curves(results["histories"], figs / "training_curves.png")
    if results.get("curve"):
        plot_size_curve(results, figs / "train_size_curve.png")
    keys = sorted({k for p in preds.values() for k in p})
    by_key = {ep.key: ep for ep in episodes}
    examples = []
    for seed, episode, step in keys:
        ep = by_key[seed, episode]
        j = next(k for k in range(len(ep.steps)) if ep.frame_key(k) == (seed, episode, step))
        if ep.stored_x is not None:
            betp_m = ep.stored_x[j, CLASSES.index("moving")]
        else:
            betp_m = filter_episode(ep, generation_params)[j, CLASSES.index("moving")]
        examples.append({
            "title": f"seed {seed} ep {episode} step {step}",
            "betp_moving": betp_m,
            "predictions": {lab: p[seed, episode, step] for lab, p in preds.items()
                            if (seed, episode, step) in p},
            "labels": ep.labels[j],
        })
    if examples:
        plot_examples(examples, figs / "examples.png")
    atomic_write_text(out / "results.md", markdown_table(results))
    write_json(out / "results.json", results)
