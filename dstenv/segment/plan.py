"""What a benchmark scores: the test drives and the segmenters, tuned and trained.

:func:`split_drives` turns a test split into :class:`~dstenv.segment.replay.Episode`
drives (replayed through the simulator and checked against the stored BetP, or
rebuilt from the stored frames of evaluation-only data). :func:`plan_segmenters`
builds every segmenter of a benchmark configuration: DST presets, ``dst-tuned``
and ``dst-complete`` (tuned on replayed *training* drives only), the networks
(one per training seed, and their ``no_map`` fine-tunes on the training drives fused
without a map: :mod:`dstenv.segment.netplan`), the training-set-size curve and given
checkpoints.
Nothing here scores the test drives: :func:`dstenv.segment.score.score` does.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from dstenv.config import ConfigError
from dstenv.dst.params import DSTParams
from dstenv.segment.replay import (
    Episode,
    check_replay,
    filter_period,
    generation_params,
    record_episodes,
)
from dstenv.segment.shardindex import (
    episode_targets,
    shard_attrs,
    split_index,
    stored_episodes,
    stored_inputs,
)
from dstenv.segment.segmenters import DSTFreeSegmenter, DSTSegmenter, Segmenter

__all__ = ["Drives", "Plan", "split_drives", "plan_segmenters", "fixed_params"]

#: stored frames of the first drives compared with a re-run of the filter
_CHECK_FRAMES = 8


@dataclass
class Drives:
    """The test drives of a benchmark and where they come from."""

    episodes: list[Episode]
    generation_params: DSTParams
    config: dict[str, Any]
    source: str
    evaluation_only: bool
    refilter_reason: str | None
    channels: int

    def describe(self) -> dict[str, Any]:
        """JSON-compatible facts for ``results["data"]``."""
        ep = self.episodes[0]
        return {
            "source": self.source,
            "evaluation_only": self.evaluation_only,
            "test_frames": int(sum(len(e.steps) for e in self.episodes)),
            "test_episodes": len(self.episodes),
            "test_maps": len({e.seed for e in self.episodes}),
            "grid_shape": [int(v) for v in ep.labels.shape[1:]],
            "cell_size": ep.cell_size,
            "filter_period": filter_period(self.config),
            "generation_dst_params": self.generation_params.to_dict(),
            "refilter": self.refilter_reason or "ok",
        }


@dataclass
class Plan:
    """Segmenters to score and what the report needs to know about them."""

    segmenters: list[Segmenter] = field(default_factory=list)
    kinds: dict[str, str] = field(default_factory=dict)
    described: dict[str, dict] = field(default_factory=dict)
    seed_groups: dict[str, list[str]] = field(default_factory=dict)
    curve: dict[str, int] = field(default_factory=dict)
    unscored: dict[str, str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)  # for the report (e.g. resolution_note)
    histories: dict[str, Any] = field(default_factory=dict)
    search: dict[str, Any] | None = None

    def add(self, seg: Segmenter, kind: str, describe: dict | None = None) -> None:
        if seg.label in self.kinds:
            raise ValueError(f"two segmenters are labelled {seg.label!r}")
        self.segmenters.append(seg)
        self.kinds[seg.label] = kind
        self.described[seg.label] = describe if describe is not None else seg.describe()


def _refilter_check(episodes: list[Episode], params: DSTParams) -> str | None:
    """``None`` if re-filtering the first stored frames reproduces their BetP, else why not."""
    for ep in episodes[:2]:
        k = min(len(ep.steps), _CHECK_FRAMES)
        head = Episode(ep.seed, ep.sensor[:k], ep.gis[:k], ep.poses[:k], ep.steps[:k],
                       ep.labels[:k], ep.visible[:k], ep.cell_size, ep.episode)
        try:
            check_replay(head, ep.stored_x[:k], ep.labels[:k], params)
        except RuntimeError as exc:
            return f"re-running the filter over the stored inputs is not exact: {exc}"
    return None


def _subset(ep: Episode, keep: Any) -> Episode | None:
    """``ep`` scored only at the frames ``keep`` marks (its history kept)."""
    if keep.all():
        return ep
    if not keep.any():
        return None
    return Episode(ep.seed, ep.sensor, ep.gis, ep.poses, ep.steps[keep], ep.labels[keep],
                   ep.visible[keep], ep.cell_size, ep.episode,
                   None if ep.stored_x is None else ep.stored_x[keep], ep.history, ep.period,
                   None if ep.stored_steps is None else ep.stored_steps[keep], ep.row_steps)


def _source_steps(ep: Episode) -> Any:
    return ep.steps if ep.stored_steps is None else ep.stored_steps


def _from_step(ep: Episode, first: int) -> Episode | None:
    """``ep`` scored only at source steps ``>= first`` (its history kept)."""
    return _subset(ep, _source_steps(ep) >= first)


def steps_before(ep: Episode, stop: int) -> Episode | None:
    """``ep`` scored only at source steps ``< stop`` (``None`` if it has none there): the
    labelled frames a real drive lends to fine-tuning and tuning, never scored."""
    return _subset(ep, _source_steps(ep) < stop)


def split_drives(test_ds: Any, no_train: bool, progress: bool,
                 log: Callable[[str], None], from_step: int = 0) -> Drives:
    """The test split as drives (module docstring).

    Args:
        test_ds: :class:`dstenv.data.ShardDataset` of the test split.
        no_train: the data has no train split (evaluation only).
        progress: tqdm bars.
        log: one-line messages.
        from_step: score only frames at source steps ``>= from_step``.

    Raises:
        RuntimeError: a replay that does not reproduce the stored frames.
    """
    frames, config = split_index(test_ds.files)
    source = shard_attrs(test_ds.files).get("source", "sim")
    gen = generation_params(config)
    channels = int(test_ds[0]["x"].shape[0])
    evaluation_only = no_train or source == "kitti"
    reason = None
    if evaluation_only:
        pairs, reason = stored_episodes(frames, config, require_history=False)
        episodes = [ep for ep, _ in pairs]
        if reason is None:
            reason = _refilter_check(episodes, gen)
            for ep in episodes if reason else ():
                ep.history = False
        if reason:
            log(f"DST with other parameters than the stored ones cannot be scored: {reason}")
    else:
        episodes = record_episodes(config, episode_targets(frames), progress)
        checked: set[int] = set()  # the first two drives and one per episode index
        for i, ep in enumerate(episodes):
            x, labels = stored_inputs(frames, ep.key, ep.steps)
            ep.stored_x = x
            if i < 2 or ep.episode not in checked:
                check_replay(ep, x, labels, gen)
                checked.add(ep.episode)
    if from_step:
        episodes = [e for e in (_from_step(ep, from_step) for ep in episodes) if e is not None]
        if not episodes:
            raise ValueError(f"score_from_step {from_step}: no test frame at or after it")
    return Drives(episodes, gen, config, source, evaluation_only, reason, channels)


def fixed_params(value: Mapping[str, Any], key: str, inner: str = "params") -> dict[str, Any]:
    """Parameters given as a config value: the fields themselves, or a ``describe``
    entry / a whole segmenter row of a results.json, whose ``inner`` entry is used
    (``"params"``: DST parameters; ``"completion"``: ``dst-complete``'s box sizes).

    Raises:
        ConfigError: naming ``key`` when nothing usable is found.
    """
    v = dict(value)
    if "describe" in v:
        v = dict(v["describe"])
    if isinstance(v.get(inner), Mapping):
        return dict(v[inner])
    if any(isinstance(x, Mapping) for x in v.values()):
        raise ConfigError(
            f"{key}: expected parameter values or a results.json segmenter entry holding "
            f"'{inner}', got keys {', '.join(sorted(v))}"
        )
    return v


def resolution_note(seg: Any, cell_size: float | None) -> str | None:
    """A note when a checkpoint trained on other cells than the drives' is scored (it
    runs, but off the resolution it learned); ``None`` when they agree or are unknown."""
    trained = getattr(seg, "trained_cell_size", None)
    if not trained or not cell_size or abs(trained - cell_size) <= 1e-6:
        return None
    return (f"note: {getattr(seg, 'checkpoint', seg.label)} was trained on cells of "
            f"{trained:g} m, these drives have {cell_size:g} m: its scores are of a network "
            "used at another resolution")


def _train_drives(cfg: Mapping[str, Any], train_ds: Any, progress: bool) -> list[Episode]:
    frames, config = split_index(train_ds.files)
    return record_episodes(config, episode_targets(frames, cfg["tune"]["episodes"]), progress)


def _add_dst(plan: Plan, seg: DSTSegmenter, drives: Drives) -> bool:
    """Add a DST row, or mark it unscored when its parameters are not the stored ones
    and the drives cannot be re-filtered; returns whether it was added."""
    if drives.refilter_reason and seg.params != drives.generation_params:
        plan.unscored[seg.label] = drives.refilter_reason
        return False
    plan.add(seg, "dst")
    return True


def _dst_rows(cfg: Mapping[str, Any], drives: Drives, train: Callable[[], list[Episode]],
              plan: Plan, progress: bool, log: Callable[[str], None],
              timings: dict[str, float]) -> None:
    from dstenv.segment.complete import DSTCompleteSegmenter, tune_completion
    from dstenv.segment.registry import create_segmenter
    from dstenv.segment.tune import tune_dst_params

    gen = drives.generation_params
    presets = [create_segmenter("dst", preset=p) for p in cfg["dst_presets"]]
    if drives.evaluation_only and all(s.params != gen for s in presets):
        presets.insert(0, DSTSegmenter(gen, "dst", "dst (stored)"))
    for seg in presets:
        _add_dst(plan, seg, drives)
    if cfg["dst_free"]:  # the generation parameters, as the goal's reference
        _add_dst(plan, DSTFreeSegmenter(gen), drives)
    tuned = None
    if cfg["tune"]["params"]:
        tuned = DSTSegmenter(DSTParams.from_dict(fixed_params(cfg["tune"]["params"],
                                                               "tune.params")),
                             "dst-tuned", "dst-tuned")
    elif cfg["tune"]["enabled"] and not drives.evaluation_only:
        t = time.perf_counter()
        best, trace = tune_dst_params(train(), budget=cfg["tune"]["budget"],
                                      seed=cfg["tune"]["seed"], progress=progress,
                                      scope=cfg["tune"]["scope"])
        tuned = DSTSegmenter(best, "dst-tuned", "dst-tuned", info={"tuning": trace})
        timings["tune_s"] = time.perf_counter() - t
        log(f"dst-tuned: train mIoU ({trace['scope']}) {trace['start_miou']:.3f} (default) -> "
            f"{trace['best_miou']:.3f}")
    elif cfg["tune"]["enabled"]:
        plan.unscored["dst-tuned"] = (
            "no train split to tune on; set tune.params (e.g. the dst-tuned entry of a "
            "simulated benchmark's results.json) to score fixed tuned parameters")
    if tuned is not None and not _add_dst(plan, tuned, drives):
        tuned = None
    if not cfg["complete"]["enabled"]:
        return
    base = tuned.params if tuned is not None else gen
    cell = drives.episodes[0].cell_size
    if cfg["complete"]["params"]:
        settings = fixed_params(cfg["complete"]["params"], "complete.params", "completion")
        plan.add(DSTCompleteSegmenter(base, cell, settings), "baseline")
    elif not drives.evaluation_only:
        t = time.perf_counter()
        settings, trace = tune_completion(train(), base, cfg["complete"]["scope"],
                                          progress=progress)
        timings["tune_complete_s"] = time.perf_counter() - t
        plan.add(DSTCompleteSegmenter(base, cell, settings, {"search": trace}), "baseline")
        log(f"dst-complete: {settings} (train mIoU {trace['best_miou']:.3f}, "
            f"{trace['scope']} cells)")
    else:
        plan.unscored["dst-complete"] = (
            "no train split to tune the completion on; set complete.params (e.g. the "
            "dst-complete entry of a simulated benchmark's results.json)")


def plan_segmenters(cfg: Mapping[str, Any], drives: Drives, datasets: Mapping[str, Any],
                    checkpoints: Sequence[str | Path], device: torch.device, out: Path,
                    progress: bool, log: Callable[[str], None],
                    timings: dict[str, float],
                    dst_rows: Sequence[DSTSegmenter] = ()) -> Plan:
    """Every segmenter of a benchmark configuration (module docstring).

    Args:
        cfg: the full benchmark configuration.
        drives: :func:`split_drives`.
        datasets: ``{"train", "val"}`` :class:`dstenv.data.ShardDataset` objects.
        checkpoints: trained networks to score as well: paths, or ``(label, path)``.
        device: where networks train and run.
        out: output directory (``models/``, ``curve/``).
        progress, log: tqdm bars, one-line messages.
        timings: receives stage durations [s].
        dst_rows: more DST rows with fixed parameters (e.g. tuned on a real drive's
            fine-tuning frames); each needs the drives' filter history.
    """
    from dstenv.segment.evaluate import load_checkpoints

    taken = () if drives.evaluation_only else cfg["models"]
    pairs = [c if isinstance(c, tuple) else (None, c) for c in checkpoints]
    extra = load_checkpoints([p for _, p in pairs], drives.channels, device=device, taken=taken)
    cell = drives.episodes[0].cell_size if drives.episodes else None
    plan = Plan()
    for (label, _), seg in zip(pairs, extra):
        seg.label = label or seg.label
        note = resolution_note(seg, cell)
        if note:
            log(note)
            plan.notes.append(note)
    cache: list[list[Episode]] = []

    def train_eps() -> list[Episode]:  # replayed once, shared by both searches
        if not cache:
            cache.append(_train_drives(cfg, datasets["train"], progress))
        return cache[0]

    _dst_rows(cfg, drives, train_eps, plan, progress, log, timings)
    for seg in dst_rows:
        _add_dst(plan, seg, drives)
    if not drives.evaluation_only:
        from dstenv.segment.netplan import plan_networks

        plan_networks(cfg, datasets, device, out, plan, progress, log, timings)
    elif not extra:
        for name in cfg["models"]:
            plan.unscored[name] = (
                "not trained: evaluation-only data has no train split (give --checkpoint)")
    for seg in extra:
        plan.add(seg, "learned", {**seg.describe(), "checkpoint": seg.checkpoint})
    return plan
