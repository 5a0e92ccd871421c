"""From per-drive counts to the JSON-compatible results of a benchmark.

:func:`segmenter_results` summarises :class:`dstenv.segment.score.Scores` (every
scope with bootstrap intervals over drives, object-level recall/precision,
training seeds pooled), :func:`goal` and :func:`real_goal` evaluate the goals of
issue 14 from the same counts. The schema is documented in ``docs/benchmark.md``
(:data:`SCHEMA_VERSION`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from dstenv.dst.frame import CLASSES
from dstenv.segment.score import DISTANCE_BANDS, OBJECT_CLASSES, SCOPES, Scores
from dstenv.segment.stats import (
    confusion_summary,
    diff_ci,
    iou_batch,
    miou_batch,
    object_summary,
    resample_weights,
)

__all__ = ["SCHEMA_VERSION", "HEADLINE", "segmenter_results", "goal", "real_goal", "tie_summary"]

#: version of the results.json layout (docs/benchmark.md); bump on any breaking change
SCHEMA_VERSION: int = 2
#: the scope of the main table and the goal (dstenv.segment.score)
HEADLINE: str = "observed"
#: goal thresholds of issue 14
MARGIN_SIM: float = 0.10
MARGIN_REAL: float = 0.10
#: the same for networks fine-tuned on labelled real frames (issue 14: >= 0.15)
MARGIN_REAL_FINETUNED: float = 0.15


def _seed_ci(values: list[float]) -> list[float] | None:
    """Student-t 95 % interval of the mean over training seeds (``None`` below 2 seeds)."""
    from scipy import stats

    v = np.asarray([x for x in values if x is not None], dtype=np.float64)
    if v.size < 2:
        return None
    half = stats.t.ppf(0.975, v.size - 1) * v.std(ddof=1) / np.sqrt(v.size)
    return [float(v.mean() - half), float(v.mean() + half)]


def segmenter_results(
    scores: Scores,
    kinds: Mapping[str, str],
    described: Mapping[str, dict],
    seed_groups: Mapping[str, Sequence[str]] | None = None,
    resamples: int = 1000,
    seed: int = 0,
) -> tuple[dict[str, Any], dict[str, dict[str, np.ndarray]], np.ndarray]:
    """The ``segmenters`` section of results.json.

    Args:
        scores: the per-drive counts.
        kinds: label -> ``"dst"``, ``"baseline"`` (non-learned, not pure DST) or
            ``"learned"``.
        described: label -> :meth:`Segmenter.describe`.
        seed_groups: row label -> labels of the runs of that model with different
            training seeds; their counts are pooled into the row (same drives) and
            the spread over seeds is reported in ``"seeds"``.
        resamples, seed: bootstrap settings (:mod:`dstenv.segment.stats`).

    Returns:
        ``(segmenters, confusion, weights)``: the JSON section; label -> scope ->
        ``(E, C, C)`` per-drive matrices of each row (for paired goals); the
        bootstrap weights.
    """
    weights = resample_weights(scores.clusters, resamples, seed)
    groups = dict(seed_groups or {})
    grouped = {lab for labs in groups.values() for lab in labs}
    rows: dict[str, tuple[dict[str, np.ndarray], np.ndarray, list[str]]] = {}
    for label in scores.confusion:
        if label in grouped:
            continue
        rows[label] = (scores.confusion[label], scores.objects[label], [label])
    for row, labs in groups.items():
        labs = [lab for lab in labs if lab in scores.confusion]
        if not labs:
            continue
        conf = {sc: sum(scores.confusion[lab][sc] for lab in labs) for sc in SCOPES}
        rows[row] = (conf, sum(scores.objects[lab] for lab in labs), labs)
    out, confusion = {}, {}
    for label, (conf, objs, labs) in rows.items():
        entry: dict[str, Any] = {sc: confusion_summary(conf[sc], weights, CLASSES) for sc in SCOPES}
        entry["objects"] = object_summary(objs, weights, OBJECT_CLASSES, DISTANCE_BANDS)
        entry["kind"] = kinds[labs[0]]
        entry["describe"] = described[labs[0]]
        if len(labs) > 1 or label in groups:
            per = {
                lab: {sc: confusion_summary(scores.confusion[lab][sc], weights[:0], CLASSES)
                      for sc in SCOPES}
                for lab in labs
            }
            entry["seeds"] = {
                "runs": labs,
                "describe": [described[lab] for lab in labs],
                **{
                    sc: {
                        "miou": [per[lab][sc]["miou"] for lab in labs],
                        "miou_mean": float(np.mean([per[lab][sc]["miou"] or np.nan
                                                    for lab in labs])),
                        "miou_ci": _seed_ci([per[lab][sc]["miou"] for lab in labs]),
                    }
                    for sc in SCOPES
                },
            }
        out[label], confusion[label] = entry, conf
    return out, confusion, weights


def _pick(segs: Mapping[str, Any], kinds: Sequence[str], scope: str) -> str | None:
    cands = [k for k, v in segs.items() if v["kind"] in kinds and v[scope]["miou"] is not None]
    return max(cands, key=lambda k: segs[k][scope]["miou"]) if cands else None


def _class_diff(k: int):
    return lambda cm: iou_batch(cm)[..., k]


def goal(
    segs: Mapping[str, Any],
    confusion: Mapping[str, Mapping[str, np.ndarray]],
    weights: np.ndarray,
    scope: str = HEADLINE,
    margin: float = MARGIN_SIM,
) -> dict[str, Any] | None:
    """Simulated goal: the best network beats the best non-learned segmenter.

    Met when, over ``scope`` cells, the mIoU margin is ``>= margin`` and the paired
    95 % intervals (bootstrap over drives) of the mIoU, moving-IoU and static-IoU
    differences all exclude zero.
    """
    bl, bd = _pick(segs, ("learned",), scope), _pick(segs, ("dst", "baseline"), scope)
    if bl is None or bd is None:
        return None
    a, b = confusion[bl][scope], confusion[bd][scope]
    d_miou, ci_miou = diff_ci(a, b, weights, miou_batch)
    res: dict[str, Any] = {
        "scope": scope,
        "best_learned": bl,
        "best_learned_miou": segs[bl][scope]["miou"],
        "best_baseline": bd,
        "best_baseline_miou": segs[bd][scope]["miou"],
        "margin": d_miou,
        "margin_ci": ci_miou,
        "margin_goal": margin,
        "margin_met": d_miou >= margin and ci_miou is not None and ci_miou[0] > 0,
    }
    for name in ("moving", "static"):
        d, ci = diff_ci(a, b, weights, _class_diff(CLASSES.index(name)))
        ok = bool(np.isfinite(d)) and ci is not None and ci[0] > 0
        res[f"{name}_diff"] = d if np.isfinite(d) else None
        res[f"{name}_diff_ci"] = ci
        res[f"{name}_met"] = ok
    return res


def real_goal(
    segs: Mapping[str, Any],
    confusion: Mapping[str, Mapping[str, np.ndarray]],
    weights: np.ndarray,
    reference: str,
    scope: str = "visible",
    margin: float = MARGIN_REAL,
    finetuned: Sequence[str] = (),
    finetuned_margin: float = MARGIN_REAL_FINETUNED,
) -> dict[str, Any] | None:
    """Real-data goal: each network beats pure DST (``reference``) by ``margin`` IoU
    on moving and on static over ``scope`` cells (paired intervals reported); the
    networks labelled in ``finetuned`` (trained on real frames) by ``finetuned_margin``.
    Each row records the margin it is held to, and its difference (paired interval)
    to the strongest non-learned row of each class (``"strongest"``: by that class's
    IoU over the drives; not part of the goal)."""
    if reference not in segs:
        return None
    strongest: dict[str, dict[str, Any]] = {}
    for name in ("moving", "static"):
        k = CLASSES.index(name)
        ious = {lab: float(iou_batch(confusion[lab][scope].sum(0))[k])
                for lab, v in segs.items() if v["kind"] != "learned"}
        ious = {lab: x for lab, x in ious.items() if np.isfinite(x)}
        if ious:
            best = max(ious, key=lambda lab: ious[lab])
            strongest[name] = {"baseline": best, "iou": ious[best]}
    out: dict[str, Any] = {"scope": scope, "reference": reference, "margin_goal": margin,
                           "margin_finetuned": finetuned_margin, "strongest": strongest,
                           "networks": {}}
    for label, v in segs.items():
        if v["kind"] != "learned":
            continue
        m = finetuned_margin if label in finetuned else margin
        row: dict[str, Any] = {"margin": m}
        for name in ("moving", "static"):
            d, ci = diff_ci(confusion[label][scope], confusion[reference][scope], weights,
                            _class_diff(CLASSES.index(name)))
            row[name] = {"diff": d if np.isfinite(d) else None, "ci": ci,
                         "met": bool(np.isfinite(d) and d >= m)}
            if name in strongest:
                d, ci = diff_ci(confusion[label][scope],
                                confusion[strongest[name]["baseline"]][scope], weights,
                                _class_diff(CLASSES.index(name)))
                row[name]["vs_strongest"] = {"diff": d if np.isfinite(d) else None, "ci": ci}
        out["networks"][label] = row
    return out if out["networks"] else None


def tie_summary(scores: Scores) -> dict[str, Any]:
    """Cells where BetP(building) == BetP(static) is the maximum (the no-map tie)."""
    tied, labelled = (int(v) for v in scores.ties.sum(0))
    return {
        "tied_cells": tied,
        "labelled_cells": labelled,
        "share": tied / labelled if labelled else None,
        "rule": "argmax takes the first of the tied classes in CLASSES order: building",
    }
