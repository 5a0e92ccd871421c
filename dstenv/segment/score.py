"""One orchestration: score segmenters on drives, whatever their source.

:func:`score` is the only place that turns segmenters and drives
(:class:`dstenv.segment.replay.Episode`: replayed simulator episodes, stored
simulated frames, converted KITTI sequences) into confusion matrices. The
simulated benchmark, the benchmark on stored data and ``dstenv kitti evaluate``
all call it, so every number of a report is counted the same way.

Scopes (cells a confusion matrix counts)
----------------------------------------
``observed`` (the headline)
    cells the sensor has observed (not ``unknown``) in any sweep the filter fused
    in the episode up to the scored one, carried into the current ego frame by the ego motion with
    the filter's own nearest-neighbour warp
    (:func:`dstenv.dst.reference.source_cells`). This is what the perception grid
    could know: the DST filter holds evidence there, and a cell never observed in
    the drive can only be guessed from priors (the map and the usual shapes of
    cars). It is wider than ``visible``: a parked car seen 2 s ago and now hidden
    behind a van still counts, as it does for a driver. For drives without their
    filter history (stored frames strided beyond the filter period) it equals
    ``visible``; :attr:`Scores.observed_definition` says which.
``visible``
    cells observed in the current sweep.
``all`` (amodal)
    every labelled cell, including car bodies and building interiors no sweep
    ever reached: scoring there mostly measures shape completion.

Object-level counts
-------------------
An *object* is an 8-connected component of cells labelled ``static`` (resp.
``moving``) in one frame (the labels hold no instance ids; two parked cars
touching each other count as one object). An object is counted when at least one
of its cells is observed; it is *recovered* when the majority of its observed
cells predicted static-or-moving are predicted with its own class (a car whose
observed cells are all predicted ``building`` is missed). Precision uses the
components of predicted ``static`` (``moving``) cells among the observed cells; a
predicted object is correct when most of its cells carry that label. Objects are
binned by the distance of their centroid to the ego cell (:data:`DISTANCE_BANDS`).

Every count is kept per drive so that :mod:`dstenv.segment.stats` can bootstrap
over drives.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import torch
from tqdm import tqdm

from dstenv.data.inputs import network_input, past_rows, past_sensor
from dstenv.dst.frame import CLASSES
from dstenv.dst.params import DSTParams
from dstenv.frame import IGNORE_INDEX
from dstenv.grid import relative_pose
from dstenv.segment.metrics import confusion_matrix
from dstenv.segment.replay import Episode, filter_episode
from dstenv.segment.segmenters import DSTSegmenter, Segmenter

__all__ = [
    "SCOPES",
    "DISTANCE_BANDS",
    "OBJECT_CLASSES",
    "Scores",
    "score",
    "observed_cells",
    "object_counts",
    "tie_cells",
    "past_grids",
]

#: cell sets scored, headline first (module docstring)
SCOPES: tuple[str, ...] = ("observed", "visible", "all")
#: [m] edges of the distance bands of the object-level counts
DISTANCE_BANDS: tuple[float, ...] = (0.0, 10.0, 20.0, float("inf"))
#: classes whose objects are counted
OBJECT_CLASSES: tuple[str, ...] = ("static", "moving")
_BUILDING, _STATIC = CLASSES.index("building"), CLASSES.index("static")


def observed_cells(episode: Episode) -> np.ndarray:
    """Cells observed so far in the episode, at each scored step.

    Returns:
        ``(K, H, W) bool``: observed at some step ``<=`` the scored one and carried
        into its ego frame (module docstring); ``episode.visible`` for drives
        without history.
    """
    from dstenv.dst.reference import source_cells

    if not episode.history:
        return episode.visible.copy()
    h, w = episode.sensor.shape[1:]
    out = np.zeros((len(episode.steps), h, w), dtype=bool)
    wanted = {int(s): k for k, s in enumerate(episode.steps)}
    seen = np.zeros((h, w), dtype=bool)
    prev = None
    last = int(episode.steps[-1]) if len(episode.steps) else -1
    for t in range(0, last + 1, episode.period):  # the sweeps the filter fused
        if prev is not None:
            motion = relative_pose(episode.poses[prev], episode.poses[t])
            if motion != (0.0, 0.0, 0.0):
                si, sj, valid = source_cells((h, w), episode.cell_size, motion)
                seen = valid & seen[np.clip(si, 0, h - 1), np.clip(sj, 0, w - 1)]
        seen |= episode.sensor[t] != 0
        if t in wanted:
            out[wanted[t]] = seen
        prev = t
    return out


def object_counts(
    pred: np.ndarray, labels: np.ndarray, observed: np.ndarray, cell_size: float
) -> np.ndarray:
    """Object-level counts of one frame (module docstring).

    Args:
        pred: ``(H, W) int`` predicted classes.
        labels: ``(H, W) int`` true classes (or the ignore index).
        observed: ``(H, W) bool`` cells that count.
        cell_size: [m].

    Returns:
        ``(len(OBJECT_CLASSES), len(DISTANCE_BANDS) - 1, 4) int64``: per class and
        band ``[true objects, recovered, predicted objects, correct predictions]``.
    """
    from scipy import ndimage

    h, w = labels.shape
    ii, jj = np.mgrid[0:h, 0:w]
    dist = np.hypot(ii - h // 2, jj - w // 2) * cell_size
    edges = np.asarray(DISTANCE_BANDS)
    out = np.zeros((len(OBJECT_CLASSES), len(edges) - 1, 4), dtype=np.int64)
    eight = np.ones((3, 3), dtype=bool)
    dyn = (pred == _STATIC) | (pred == CLASSES.index("moving"))

    def band(mask: np.ndarray) -> int:
        d = float(dist[mask].mean())
        return int(np.searchsorted(edges, d, side="right") - 1)

    for c, name in enumerate(OBJECT_CLASSES):
        k = CLASSES.index(name)
        comps, n = ndimage.label(labels == k, structure=eight)
        for obj in range(1, n + 1):
            cells = (comps == obj) & observed
            if not cells.any():
                continue
            b = band(comps == obj)
            out[c, b, 0] += 1
            votes = cells & dyn
            if votes.any() and 2 * int((pred[votes] == k).sum()) > int(votes.sum()):
                out[c, b, 1] += 1
        comps, n = ndimage.label((pred == k) & observed, structure=eight)
        for obj in range(1, n + 1):
            cells = comps == obj
            b = band(cells)
            out[c, b, 2] += 1
            if 2 * int((labels[cells] == k).sum()) > int(cells.sum()):
                out[c, b, 3] += 1
    return out


def tie_cells(betp: np.ndarray, labels: np.ndarray) -> tuple[int, int]:
    """Cells where BetP(building) equals BetP(static) and both are the largest.

    Without a map the masses of ``building`` and ``static`` only ever come together
    (occupied evidence cannot tell them apart), so the two BetP are equal in every
    occupied cell and argmax resolves the tie to the first, ``building``
    (:data:`dstenv.dst.CLASSES` order): DST can then never predict ``static``.

    Args:
        betp: ``(K, 5, H, W)`` BetP (channels 0..4 of the input).
        labels: ``(K, H, W)`` labels; ignored cells are not counted.

    Returns:
        ``(tied cells, labelled cells)``.
    """
    b, s = betp[:, _BUILDING], betp[:, _STATIC]
    top = betp[:, :5].max(1)
    keep = labels != IGNORE_INDEX
    tied = (np.abs(b - s) <= 1e-6) & (b >= top - 1e-6) & keep
    return int(tied.sum()), int(keep.sum())


@dataclass
class Scores:
    """Per-drive counts of every segmenter (JSON-free; see :mod:`dstenv.segment.stats`).

    Attributes:
        drives: ``(seed, episode)`` of each scored drive, in order.
        clusters: ``(E,) int64`` bootstrap cluster of each drive: its map seed (the
            episodes of one map are not independent).
        confusion: label -> scope -> ``(E, C, C) int64`` confusion matrices.
        objects: label -> ``(E, 2, bands, 4) int64`` :func:`object_counts` sums.
        ties: ``(E, 2) int64`` :func:`tie_cells` of the generation BetP per drive.
        frames: scored frames per drive ``(E,) int64``.
        unscored: label -> why it could not be scored on these drives.
        examples: label -> ``{(seed, episode, step): (H, W) prediction}``.
        observed_definition: ``"history"`` or ``"visible"`` (module docstring).
    """

    drives: list[tuple[int, int]]
    clusters: np.ndarray
    confusion: dict[str, dict[str, np.ndarray]]
    objects: dict[str, np.ndarray]
    ties: np.ndarray
    frames: np.ndarray
    unscored: dict[str, str] = field(default_factory=dict)
    examples: dict[str, dict[tuple[int, int, int], np.ndarray]] = field(default_factory=dict)
    observed_definition: str = "history"


def _key(p: DSTParams) -> tuple:
    return tuple(round(v, 9) for v in p.to_dict().values())



def past_grids(episode: Episode) -> np.ndarray:
    """``(K, H, W) uint8``: for each scored frame, the drive's sensor grid
    :data:`~dstenv.data.datasets.PAST_STEPS` steps earlier in its ego frame (all
    unknown where the drive holds no such step), as ``fcn10+sensor+past`` reads it."""
    rows = (np.arange(len(episode.sensor)) if episode.row_steps is None
            else np.asarray(episode.row_steps))
    prow = past_rows(rows)
    out = np.zeros((len(episode.steps), *episode.sensor.shape[1:]), np.uint8)
    for k, row in enumerate(episode.steps):
        j = int(prow[row])
        if j >= 0:
            out[k] = past_sensor(episode.sensor[j], episode.poses[j], episode.poses[row],
                                 episode.cell_size)
    return out

def score(
    segmenters: Sequence[Segmenter],
    episodes: Sequence[Episode],
    generation_params: DSTParams,
    batch_size: int = 8,
    examples: Sequence[tuple[int, int, int]] = (),
    progress: bool = False,
) -> Scores:
    """Score every segmenter on the same frames of the same drives.

    A DST segmenter (:class:`DSTSegmenter` and subclasses) gets the BetP of a
    filter run with its own parameters over the drive's inputs (argmax of the
    stored BetP when they are the generation parameters and the drive has no
    history; unscorable otherwise), with the drive's sensor grids when its ``inputs``
    say so (``dst-free``). Any other segmenter (a network) reads the
    drive's ``stored_x`` if set, else the filter run with ``generation_params``,
    and, when its ``inputs`` are ``fcn10+sensor`` (``+past``), the drive's sensor grids
    (and :func:`past_grids`; :func:`dstenv.data.datasets.network_input`).

    Args:
        segmenters: distinct ``label`` values.
        episodes: the drives.
        generation_params: the DST parameters the drives' data were produced with.
        batch_size: frames per network call.
        examples: frame keys ``(seed, episode, step)`` whose predictions are kept.
        progress: a tqdm bar over drives.

    Returns:
        :class:`Scores`.
    """
    labels_ = [s.label for s in segmenters]
    if len(set(labels_)) != len(labels_):
        raise ValueError(f"segmenter labels must be unique, got {labels_}")
    if not episodes:
        raise ValueError("no drives to score")
    nc, e = len(CLASSES), len(episodes)
    n_obj = (len(OBJECT_CLASSES), len(DISTANCE_BANDS) - 1, 4)
    conf = {s.label: {sc: np.zeros((e, nc, nc), np.int64) for sc in SCOPES} for s in segmenters}
    objs = {s.label: np.zeros((e, *n_obj), np.int64) for s in segmenters}
    ties = np.zeros((e, 2), np.int64)
    unscored: dict[str, str] = {}
    kept: dict[str, dict[tuple[int, int, int], np.ndarray]] = {s.label: {} for s in segmenters}
    wanted = set(map(tuple, examples))
    gen_key = _key(generation_params)
    for i, ep in enumerate(tqdm(episodes, desc="score", disable=not progress, leave=False)):
        cache: dict[tuple, np.ndarray] = {}

        def betp(params: DSTParams, ep: Episode = ep, cache: dict = cache) -> np.ndarray:
            k = _key(params)
            if k not in cache:
                if ep.history:
                    cache[k] = filter_episode(ep, params)
                elif k == gen_key:
                    cache[k] = ep.stored_x
                else:
                    raise LookupError
            return cache[k]

        x_gen = ep.stored_x if ep.stored_x is not None else betp(generation_params)
        observed = observed_cells(ep)
        labels = ep.labels.astype(np.int64)
        ties[i] = tie_cells(x_gen, labels)
        masks = {"observed": observed, "visible": ep.visible, "all": None}
        for seg in segmenters:
            if seg.label in unscored:
                continue
            if isinstance(seg, DSTSegmenter):
                try:
                    x = betp(seg.params)
                except LookupError:
                    unscored[seg.label] = (
                        f"drive {ep.key} holds stored frames only, without the filter history "
                        "needed to re-run DST with other parameters (store every filtered "
                        "frame, e.g. kitti convert --stride 1 --warmup 0)"
                    )
                    continue
                inputs = getattr(seg, "inputs", "fcn10")  # dst-free: + the sensor grid
                x = network_input(x, ep.sensor[ep.steps], inputs) if inputs != "fcn10" else x
                pred = seg.predict(torch.from_numpy(x)).numpy()
            else:
                inputs = getattr(seg, "inputs", "fcn10")
                past = past_grids(ep) if inputs == "fcn10+sensor+past" else None
                pred = np.concatenate([
                    seg.predict(torch.from_numpy(network_input(
                        x_gen[j : j + batch_size], ep.sensor[ep.steps[j : j + batch_size]],
                        inputs, None if past is None else past[j : j + batch_size]))).numpy()
                    for j in range(0, len(x_gen), batch_size)
                ])
            for sc, m in masks.items():
                conf[seg.label][sc][i] = confusion_matrix(pred, labels, nc, m)
            for k in range(len(ep.steps)):
                objs[seg.label][i] += object_counts(pred[k], labels[k], observed[k], ep.cell_size)
                fk = ep.frame_key(k)
                if fk in wanted:
                    kept[seg.label][fk] = pred[k]
    for label in unscored:
        conf.pop(label)
        objs.pop(label)
        kept.pop(label)
    return Scores(
        drives=[ep.key for ep in episodes],
        clusters=np.array([ep.seed for ep in episodes], dtype=np.int64),
        confusion=conf,
        objects=objs,
        ties=ties,
        frames=np.array([len(ep.steps) for ep in episodes], dtype=np.int64),
        unscored=unscored,
        examples=kept,
        observed_definition="history" if all(ep.history for ep in episodes) else "visible",
    )
