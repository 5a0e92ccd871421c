"""The benchmark on evaluation-only data: KITTI conversions, shards without a train split.

Such data cannot train networks, tune the DST parameters or be replayed through the
simulator, so :func:`evaluate_stored` scores what it honestly can on the stored
test frames:

* ``dst (<preset>)`` of the parameters the shards were made with, from the stored
  BetP (:func:`dstenv.segment.evaluate.stored_dst_segmenter`);
* the other ``dst_presets`` and ``dst-tuned`` with fixed ``tune.params`` (e.g. found
  by a simulated benchmark), by re-running the filter over the stored ``sensor``,
  ``gis`` and ``ego_pose`` -- only when the shards hold every filtered frame
  (:func:`dstenv.segment.replay.stored_episodes`) and that re-run reproduces the
  stored BetP; otherwise each such variant is listed in ``results["unscored"]``
  with the reason;
* every given checkpoint (e.g. trained on simulated data: sim-to-real transfer).

All segmenters are scored on the same cells (every labelled, resp. visible, cell
of every test frame).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from dstenv.dst.frame import CLASSES
from dstenv.segment import report
from dstenv.segment.evaluate import load_checkpoints, score_segmenters, stored_dst_segmenter
from dstenv.segment.metrics import ConfusionMeter
from dstenv.segment.registry import create_segmenter
from dstenv.segment.replay import (
    Episode,
    check_replay,
    filter_episode,
    filter_period,
    shard_attrs,
    split_index,
    stored_episodes,
    stored_inputs,
)
from dstenv.segment.segmenters import DSTSegmenter

__all__ = ["evaluate_stored"]

#: stored frames of the first episodes compared with a re-run of the filter
_CHECK_FRAMES = 8


def _refilter_check(episodes: list[tuple[Episode, np.ndarray]], frames: list[dict[str, Any]],
                    params: Any) -> str | None:
    """``None`` if re-filtering the first stored frames reproduces their BetP, else why not."""
    for ep, steps in episodes[:2]:
        k = min(len(steps), _CHECK_FRAMES)
        head = Episode(ep.seed, ep.sensor[:k], ep.gis[:k], ep.poses[:k], ep.steps[:k],
                       ep.labels[:k], ep.visible[:k], ep.cell_size)
        try:
            check_replay(head, *stored_inputs(frames, ep.seed, steps[:k]), params)
        except RuntimeError as exc:
            return f"re-running the filter over the stored inputs is not exact: {exc}"
    return None


def _score_refiltered(
    seg: DSTSegmenter, episodes: list[tuple[Episode, np.ndarray]], wanted: set[tuple[int, int]]
) -> tuple[ConfusionMeter, dict[tuple[int, int], np.ndarray]]:
    meter = ConfusionMeter(len(CLASSES))
    preds = {}
    for ep, steps in episodes:
        pred = seg.predict(torch.from_numpy(filter_episode(ep, seg.params)))
        meter.update(
            pred, torch.from_numpy(ep.labels.astype(np.int64)), torch.from_numpy(ep.visible)
        )
        for k, s in enumerate(steps):
            if (ep.seed, int(s)) in wanted:
                preds[(ep.seed, int(s))] = pred[k].numpy()
    return meter, preds


def evaluate_stored(
    cfg: dict[str, Any],
    test_ds: Any,
    checkpoints: Sequence[str | Path],
    device: str | torch.device,
    progress: bool,
    log: Callable[[str], None],
    source: str,
) -> tuple[dict[str, Any], list[dict[str, Any]], dict[str, dict[tuple[int, int], np.ndarray]]]:
    """Score DST variants and checkpoints on the stored test frames of evaluation-only data.

    Args:
        cfg: the full benchmark configuration (``dst_presets``, ``tune``, ``models``,
            ``eval_batch_size``, ``examples``).
        test_ds: :class:`dstenv.data.ShardDataset` of the test split (``inputs="fcn10"``).
        checkpoints: trained networks to score.
        device: where the networks run.
        progress: tqdm bars.
        log: receives one-line messages.
        source: the shards' ``source`` attribute (``"kitti"`` or ``"sim"``).

    Returns:
        ``(results, frames, preds)``: the JSON-compatible results (without
        ``preset``/``command``/``goal``), the :func:`split_index` frames and the
        example predictions (label -> ``{(seed, step): (H, W)}``) for the report.

    Raises:
        ValueError: a checkpoint whose input channels or classes do not match.
    """
    timings: dict[str, float] = {}
    frames, config = split_index(test_ds.files)
    attrs = shard_attrs(test_ds.files)
    channels = int(test_ds[0]["x"].shape[0])
    learned = load_checkpoints(checkpoints, channels, device=device)  # fail before any work
    base = stored_dst_segmenter(config)
    example = sorted(report.example_ids(frames, cfg["examples"]))
    wanted = {(frames[k]["seed"], frames[k]["step"]) for k in example}
    unscored: dict[str, str] = {}

    # DST variants: the stored BetP's own parameters need no filter run
    variants: list[DSTSegmenter] = [create_segmenter("dst", preset=p) for p in cfg["dst_presets"]]
    if cfg["tune"]["params"]:
        variants.append(create_segmenter("dst-tuned", params=cfg["tune"]["params"]))
    elif cfg["tune"]["enabled"]:
        unscored["dst-tuned"] = (
            "no train split to tune on; set tune.params (e.g. the dst-tuned params of a "
            "simulated benchmark's results.json) to score fixed tuned parameters"
        )
    stored_segs: list[Any] = [base]
    refilter = []
    for v in variants:
        if v.params == base.params:
            if v.label != base.label:
                stored_segs.append(v)
        else:
            refilter.append(v)

    t = time.perf_counter()
    meters = score_segmenters([*stored_segs, *learned], test_ds, cfg["eval_batch_size"], progress)
    timings["stored_eval_s"] = time.perf_counter() - t
    preds: dict[str, dict[tuple[int, int], np.ndarray]] = {}
    for seg in (*stored_segs, *learned):
        preds[seg.label] = {}
        for k in example:
            x = torch.as_tensor(test_ds[k]["x"])[None]
            preds[seg.label][(frames[k]["seed"], frames[k]["step"])] = seg.predict(x)[0].numpy()

    if refilter:
        t = time.perf_counter()
        episodes, reason = stored_episodes(frames, config)
        if reason is None:
            reason = _refilter_check(episodes, frames, base.params)
        if reason is not None:
            for v in refilter:
                unscored[v.label] = reason
                log(f"{v.label}: not scored: {reason}")
        else:
            for v in refilter:
                meters[v.label], preds[v.label] = _score_refiltered(v, episodes, wanted)
        timings["refilter_eval_s"] = time.perf_counter() - t
    if not learned:
        for name in cfg["models"]:
            unscored[name] = (
                "not trained: evaluation-only data has no train split (give --checkpoint)"
            )

    kinds = {s.label: "dst" for s in (*stored_segs, *refilter)}
    kinds.update({s.label: "learned" for s in learned})
    described = {s.label: s.describe() for s in (*stored_segs, *refilter)}
    described.update({s.label: {**s.describe(), "checkpoint": s.checkpoint} for s in learned})
    segmenters = {
        label: {**meters[label].summary(CLASSES), "kind": kinds[label],
                "describe": described[label]}
        for label in [s.label for s in (*stored_segs, *refilter, *learned)]
        if label in meters
    }
    preds = {label: preds[label] for label in segmenters if label in preds}  # table order
    results = {
        "config": cfg,
        "data": {
            "dir": "",
            "source": source,
            "evaluation_only": True,
            "train_frames": 0,
            "val_frames": 0,
            "test_frames": len(frames),
            "test_episodes": len({fr["seed"] for fr in frames}),
            "grid_shape": [int(v) for v in attrs["grid_shape"]],
            "cell_size": float(attrs["cell_size"]),
            "filter_period": filter_period(config),
            "generation_dst_params": base.params.to_dict(),
        },
        "segmenters": segmenters,
        "unscored": unscored,
        "histories": {},
        "timings_s": timings,
    }
    return results, frames, preds
