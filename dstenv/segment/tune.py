"""``dst-tuned``: search the DST parameters for the best mIoU on training episodes.

The paper's complaint about DST was its manual tuning. Here the numbers of
:class:`~dstenv.dst.DSTParams` (sensor and map confidence, discount alpha,
accumulator steps and thresholds) are searched automatically, on the *training*
split only, so that the FCN is compared with the strongest DST and the test
maps stay unseen:

1. the starting points: ``DSTParams.default()`` and ``DSTParams.paper()``;
2. random search: ``n_random`` points drawn uniformly in :data:`SEARCH_SPACE`;
3. coordinate search from the best point: each field in turn moves by
   ``+-step`` (clipped to its range) while it improves, the step halving after a
   sweep without improvement, until the evaluation budget is spent.

Every candidate is scored by running the filter over all training episodes
(:func:`dstenv.segment.replay.filter_episode`) and taking the mIoU of argmax BetP
over the cells of ``scope`` (:data:`dstenv.segment.score.SCOPES`; the benchmark
uses its headline scope, ``observed``). The search is deterministic for a given
``seed``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from dstenv.dst.params import DSTParams
from dstenv.segment.metrics import confusion_matrix, mean_iou
from dstenv.segment.replay import Episode, filter_episode

__all__ = ["SEARCH_SPACE", "score_params", "scope_masks", "tune_dst_params"]

#: field -> (low, high) searched range
SEARCH_SPACE: dict[str, tuple[float, float]] = {
    "sensor_confidence": (0.5, 0.99),
    "map_confidence": (0.5, 0.999),
    "alpha": (0.0, 0.95),
    "delta_inc": (0.05, 1.0),
    "delta_dec": (0.05, 1.0),
    "gamma_occupied": (0.05, 0.95),
    "gamma_conflict": (0.05, 0.95),
}


def score_params(
    episodes: Sequence[Episode],
    params: DSTParams,
    num_classes: int = 5,
    masks: Sequence[np.ndarray | None] | None = None,
) -> float:
    """mIoU of argmax BetP over ``episodes`` with ``params``.

    Args:
        masks: per episode ``(K, H, W) bool`` cells counted (``None``: all labelled).
    """
    cm = np.zeros((num_classes, num_classes), dtype=np.int64)
    for i, ep in enumerate(episodes):
        if len(ep.steps) == 0:
            continue
        pred = filter_episode(ep, params)[:, :5].argmax(1)
        mask = None if masks is None else masks[i]
        cm += confusion_matrix(pred, ep.labels.astype(np.int64), num_classes, mask)
    return mean_iou(cm)


def scope_masks(episodes: Sequence[Episode], scope: str) -> list[np.ndarray | None]:
    """Per episode, the cells of ``scope`` (``observed``, ``visible`` or ``all``)."""
    from dstenv.segment.score import SCOPES, observed_cells

    if scope not in SCOPES:
        raise ValueError(f"unknown scope {scope!r}; choose from {', '.join(SCOPES)}")
    if scope == "all":
        return [None] * len(episodes)
    return [observed_cells(ep) if scope == "observed" else ep.visible for ep in episodes]


def tune_dst_params(
    episodes: Sequence[Episode],
    budget: int = 40,
    n_random: int | None = None,
    step: float = 0.2,
    seed: int = 0,
    progress: bool = False,
    scope: str = "all",
) -> tuple[DSTParams, dict]:
    """Search :class:`DSTParams` for the best training mIoU.

    Args:
        episodes: training episodes (never the test split).
        budget: total number of parameter sets scored (>= 2).
        n_random: random samples (default: a third of the budget).
        step: initial coordinate step, as a fraction of each field's range.
        seed: seed of the random samples.
        progress: show a tqdm bar.
        scope: cells of the objective (:func:`scope_masks`).

    Returns:
        ``(best_params, trace)``; ``trace`` is JSON-compatible: ``{"budget", "scope",
        "evaluations": [{"params", "miou"}], "best_miou", "start_miou"}``.
    """
    from tqdm import tqdm

    if budget < 2:
        raise ValueError(f"tuning budget must be >= 2 evaluations, got {budget}")
    if not episodes:
        raise ValueError("no training episodes to tune the DST parameters on")
    masks = scope_masks(episodes, scope)
    rng = np.random.default_rng(seed)
    n_random = budget // 3 if n_random is None else n_random
    evaluations: list[dict] = []
    cache: dict[tuple, float] = {}
    bar = tqdm(total=budget, desc="tune dst", disable=not progress, leave=False)

    def score(p: DSTParams) -> float:
        key = tuple(round(v, 6) for v in p.to_dict().values())
        if key not in cache:
            cache[key] = score_params(episodes, p, masks=masks)
            evaluations.append({"params": p.to_dict(), "miou": _num(cache[key])})
            bar.update(1)
        return cache[key]

    def better(a: float, b: float) -> bool:
        return np.isfinite(a) and (not np.isfinite(b) or a > b)

    best = DSTParams.default()
    best_score = score(best)
    start_score = best_score
    for cand in [DSTParams.paper()] + [_sample(rng) for _ in range(n_random)]:
        if len(evaluations) >= budget:
            break
        s = score(cand)
        if better(s, best_score):
            best, best_score = cand, s
    frac = step
    while len(evaluations) < budget and frac > 1e-3:
        improved = False
        for name, (lo, hi) in SEARCH_SPACE.items():
            for sign in (1.0, -1.0):
                if len(evaluations) >= budget:
                    break
                value = float(np.clip(getattr(best, name) + sign * frac * (hi - lo), lo, hi))
                cand = replace(best, **{name: value})
                s = score(cand)
                if better(s, best_score):
                    best, best_score, improved = cand, s, True
                    break
        if not improved:
            frac /= 2
    bar.close()
    trace = {
        "budget": budget,
        "seed": seed,
        "scope": scope,
        "start_miou": _num(start_score),
        "best_miou": _num(best_score),
        "best_params": best.to_dict(),
        "evaluations": evaluations,
    }
    return best, trace


def _sample(rng: np.random.Generator) -> DSTParams:
    return DSTParams(**{k: float(rng.uniform(lo, hi)) for k, (lo, hi) in SEARCH_SPACE.items()})


def _num(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None
