"""``dst-complete``: DST plus geometric completion of vehicles, no learning.

Per-cell DST marks only the faces of a car the LIDAR hit; the rest of the body is
unknown. A person completing that grid by hand would draw a car-sized box along
the kerb behind the visible face. :class:`DSTCompleteSegmenter` does exactly that
on argmax BetP:

1. predictions = argmax BetP (the ``dst`` segmenter);
2. the kerb/lane direction field: the structure tensor of the ``navigable``
   prediction mask, smoothed over ``sigma_m``; its dominant gradient is normal to
   the road edge, so the box's long axis ``u`` is perpendicular to it. Where the
   tensor is not coherent (no road edge nearby) the component's own principal
   axis is used;
3. every 8-connected component of ``static`` (then ``moving``) predictions with at
   least ``min_cells`` cells gets a box of ``length_m`` x ``width_m``: centred on
   the component along ``u`` (at least its own extent) and, across ``v``, starting
   at the component's side facing the ego and extending away from it (the hidden
   side of an object is the far one);
4. box cells predicted ``navigable`` or ``non_navigable`` whose BetP of those two
   classes together is below ``max_free`` take the component's class (cells seen
   free carry a high free BetP and stay free; buildings are never overwritten).

:func:`tune_completion` picks ``length_m``, ``width_m``, ``min_cells`` and
``max_free`` by grid search on training drives only (the DST parameters are fixed
first, e.g. those of ``dst-tuned``).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch

from dstenv.dst.frame import CLASSES
from dstenv.dst.params import DSTParams
from dstenv.segment.segmenters import DSTSegmenter

__all__ = ["DSTCompleteSegmenter", "complete_frame", "COMPLETION_GRID", "tune_completion"]

_NAV, _NONNAV = CLASSES.index("navigable"), CLASSES.index("non_navigable")
_BUILDING, _STATIC, _MOVING = (CLASSES.index(c) for c in ("building", "static", "moving"))

#: the grid :func:`tune_completion` searches (length 0 = no completion)
COMPLETION_GRID: dict[str, tuple[float, ...]] = {
    "length_m": (0.0, 3.5, 4.5, 5.5),
    "width_m": (1.6, 2.0),
    "min_cells": (2, 5),
    "max_free": (1.01, 0.9),
}


def complete_frame(
    betp: np.ndarray,
    cell_size: float,
    length_m: float = 4.5,
    width_m: float = 1.8,
    min_cells: int = 3,
    max_free: float = 1.01,
    sigma_m: float = 1.5,
) -> np.ndarray:
    """Argmax BetP of one frame with vehicle boxes completed (module docstring).

    Args:
        betp: ``(>=5, H, W) float32`` BetP over :data:`dstenv.dst.CLASSES` first.
        cell_size: [m].
        length_m, width_m: box size [m]; ``length_m <= 0`` returns plain argmax.
        min_cells: smallest component completed.
        max_free: fill only cells with ``BetP(navigable) + BetP(non_navigable)`` below it.
        sigma_m: [m] smoothing of the direction field.

    Returns:
        ``(H, W) int64`` classes.
    """
    from scipy import ndimage

    pred = betp[:5].argmax(0).astype(np.int64)
    if length_m <= 0:
        return pred
    h, w = pred.shape
    free = betp[_NAV] + betp[_NONNAV]
    road = (pred == _NAV).astype(np.float64)
    gi, gj = ndimage.sobel(road, 0), ndimage.sobel(road, 1)
    s = sigma_m / cell_size
    jii, jij, jjj = (ndimage.gaussian_filter(v, s) for v in (gi * gi, gi * gj, gj * gj))
    half_l, wid = 0.5 * length_m / cell_size, width_m / cell_size
    reach = int(np.ceil(half_l + wid)) + 1
    out = pred.copy()
    eight = np.ones((3, 3), dtype=bool)
    for k in (_STATIC, _MOVING):
        comps, _ = ndimage.label(pred == k, structure=eight)
        for obj, sl in enumerate(ndimage.find_objects(comps), start=1):
            ci, cj = np.nonzero(comps[sl] == obj)
            if len(ci) < min_cells:
                continue
            ci, cj = ci + sl[0].start, cj + sl[1].start
            mi, mj = ci.mean(), cj.mean()
            a, b, c = jii[ci, cj].sum(), jij[ci, cj].sum(), jjj[ci, cj].sum()
            coherence = np.hypot(a - c, 2 * b) / (a + c) if a + c > 1e-9 else 0.0
            if coherence > 0.5:  # kerb-aligned: u perpendicular to the edge normal
                normal = 0.5 * np.arctan2(2 * b, a - c)
                theta = normal + np.pi / 2
            elif len(ci) >= 2:  # own principal axis
                cov = np.cov(np.stack([ci - mi, cj - mj]))
                vecs = np.linalg.eigh(cov)[1]
                theta = float(np.arctan2(vecs[1, -1], vecs[0, -1]))
            else:
                theta = 0.0
            u = np.array([np.cos(theta), np.sin(theta)])
            v = np.array([-u[1], u[0]])
            pu = (ci - mi) * u[0] + (cj - mj) * u[1]
            pv = (ci - mi) * v[0] + (cj - mj) * v[1]
            ego_v = (h // 2 - mi) * v[0] + (w // 2 - mj) * v[1]
            u0 = 0.5 * (pu.min() + pu.max())
            hu = max(half_l, 0.5 * (pu.max() - pu.min()) + 0.5)
            if ego_v < 0:  # ego on the -v side: the body extends towards +v
                v_lo, v_hi = pv.min() - 0.5, max(pv.max() + 0.5, pv.min() - 0.5 + wid)
            else:
                v_lo, v_hi = min(pv.min() - 0.5, pv.max() + 0.5 - wid), pv.max() + 0.5
            i0, i1 = max(int(mi) - reach, 0), min(int(mi) + reach + 1, h)
            j0, j1 = max(int(mj) - reach, 0), min(int(mj) + reach + 1, w)
            di, dj = np.mgrid[i0:i1, j0:j1]
            qu = (di - mi) * u[0] + (dj - mj) * u[1]
            qv = (di - mi) * v[0] + (dj - mj) * v[1]
            inside = (np.abs(qu - u0) <= hu) & (qv >= v_lo) & (qv <= v_hi)
            win = out[i0:i1, j0:j1]
            fill = inside & ((win == _NAV) | (win == _NONNAV)) & (free[i0:i1, j0:j1] < max_free)
            win[fill] = k
    return out


class DSTCompleteSegmenter(DSTSegmenter):
    """``dst-complete``: DST with its own parameters plus :func:`complete_frame`.

    Args:
        params: DST parameters of the BetP it is given (the benchmark filters with them).
        cell_size: [m] of the grids it segments.
        completion: :func:`complete_frame` keyword arguments.
        info: extra report facts (e.g. the search trace).
    """

    def __init__(
        self,
        params: DSTParams,
        cell_size: float,
        completion: dict[str, float] | None = None,
        info: dict | None = None,
    ) -> None:
        super().__init__(params, "dst-complete", "dst-complete", info)
        self.cell_size = float(cell_size)
        self.completion = dict(completion or {})

    def predict(self, x: torch.Tensor) -> torch.Tensor:
        if x.dim() != 4 or x.shape[1] < 5:
            raise ValueError(f"dst-complete needs (B, >=5, H, W) BetP input, got {tuple(x.shape)}")
        arr = x.detach().cpu().numpy()
        return torch.from_numpy(
            np.stack([complete_frame(f, self.cell_size, **self.completion) for f in arr])
        )

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "completion": self.completion, "cell_size": self.cell_size}


def tune_completion(
    episodes: Sequence[Any],
    params: DSTParams,
    scope: str = "all",
    grid: dict[str, Sequence[float]] | None = None,
    progress: bool = False,
) -> tuple[dict[str, float], dict]:
    """Grid search of the completion settings on training drives.

    Args:
        episodes: training :class:`dstenv.segment.replay.Episode` objects.
        params: the DST parameters (fixed).
        scope: cells of the objective mIoU (``"observed"``, ``"visible"`` or ``"all"``).
        grid: field -> values (default :data:`COMPLETION_GRID`).
        progress: tqdm bar.

    Returns:
        ``(best settings, trace)``; ``trace = {"scope", "grid", "evaluations":
        [{"completion", "miou"}], "best_miou"}``.
    """
    from tqdm import tqdm

    from dstenv.segment.metrics import confusion_matrix, mean_iou
    from dstenv.segment.replay import filter_episode
    from dstenv.segment.score import observed_cells

    if not episodes:
        raise ValueError("no training episodes to tune the completion on")
    grid = dict(COMPLETION_GRID if grid is None else grid)
    data = []
    for ep in episodes:
        if len(ep.steps) == 0:
            continue
        mask = {"all": None, "visible": ep.visible, "observed": observed_cells(ep)}[scope]
        data.append((filter_episode(ep, params), ep.labels.astype(np.int64), mask, ep.cell_size))
    combos = [dict(zip(grid, vals)) for vals in itertools.product(*grid.values())]
    # length 0 ignores the other fields: score it once
    combos = [c for i, c in enumerate(combos) if c["length_m"] > 0 or i == 0]
    evaluations = []
    best, best_m = combos[0], -1.0
    for combo in tqdm(combos, desc="tune dst-complete", disable=not progress, leave=False):
        cm = np.zeros((len(CLASSES), len(CLASSES)), dtype=np.int64)
        for x, labels, mask, cell in data:
            pred = np.stack([complete_frame(f, cell, **combo) for f in x])
            cm += confusion_matrix(pred, labels, len(CLASSES), mask)
        m = mean_iou(cm)
        evaluations.append({"completion": combo, "miou": float(m) if np.isfinite(m) else None})
        if np.isfinite(m) and m > best_m:
            best, best_m = combo, float(m)
    trace = {"scope": scope, "grid": {k: list(v) for k, v in grid.items()},
             "evaluations": evaluations, "best_miou": best_m}
    return {k: float(v) for k, v in best.items()}, trace
