"""Re-running the DST filter with other parameters on the same drives.

A stored frame holds BetP computed with the parameters used at generation time.
To score ``dst`` with another preset, or to tune the parameters, the filter must
run again from the raw inputs of *every* step of the episode up to the scored
frame (the accumulator and the past grid depend on all of them). We do it
honestly in two stages:

1. :func:`record_episodes` replays each episode once with
   :class:`dstenv.pipeline.Pipeline` (same configuration and episode seed as the
   shard, so the same world, LIDAR sweeps and labels) and keeps only the raw
   inputs of every step -- sensor grid, GIS grid, ego pose -- plus labels and
   ``visible`` at the scored steps: an :class:`Episode`.
2. :func:`filter_episode` runs a fresh :class:`dstenv.dst.tracker.GridTracker`
   with any :class:`~dstenv.dst.DSTParams` over those inputs, which costs only the
   filter, not the simulation, per parameter set.

:func:`check_replay` compares the replay with the generation parameters against
the stored BetP, so a replay that drifted from the stored data raises instead of
scoring different frames. :func:`split_index`, :func:`episode_targets` and
:func:`stored_inputs` find the episodes and stored frames of a shard split.

Evaluation-only datasets (KITTI conversions, or simulated shards without a train
split) cannot be replayed through the simulator. :func:`stored_episodes` rebuilds
their :class:`Episode` objects from the stored per-frame ``sensor``, ``gis`` and
``ego_pose`` instead -- honestly only when the shards hold *every* filtered step
from the first one on (otherwise the filter state between two stored frames is
lost, and it says so).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dstenv.dst.frame import CLASSES
from dstenv.dst.params import DSTParams

__all__ = [
    "Episode",
    "filter_episode",
    "record_episodes",
    "check_replay",
    "split_index",
    "episode_targets",
    "stored_inputs",
    "filter_period",
    "stored_episodes",
    "shard_attrs",
]


@dataclass
class Episode:
    """Raw inputs of one drive and its labels at the scored steps.

    Attributes:
        seed: the episode (map) seed.
        sensor: ``(T, H, W) uint8`` sensor grid at every step 0..T-1.
        gis: ``(T, H, W) uint8`` GIS grid at every step.
        poses: ``(T, 3) float64`` ego pose at every step.
        steps: ``(K,) int64`` scored steps, increasing, each < T.
        labels: ``(K, H, W) uint8`` labels at the scored steps.
        visible: ``(K, H, W) bool`` visible cells at the scored steps.
        cell_size: grid cell size [m].
    """

    seed: int
    sensor: np.ndarray
    gis: np.ndarray
    poses: np.ndarray
    steps: np.ndarray
    labels: np.ndarray
    visible: np.ndarray
    cell_size: float

    def __post_init__(self) -> None:
        t = self.sensor.shape[0]
        if self.gis.shape != self.sensor.shape or self.poses.shape != (t, 3):
            raise ValueError(
                f"episode {self.seed}: sensor {self.sensor.shape}, gis {self.gis.shape}, "
                f"poses {self.poses.shape} disagree"
            )
        if len(self.steps) and (
            np.any(np.diff(self.steps) <= 0) or self.steps[-1] >= t or self.steps[0] < 0
        ):
            raise ValueError(f"episode {self.seed}: scored steps must increase within [0, {t})")
        if self.labels.shape[0] != len(self.steps) or self.visible.shape != self.labels.shape:
            raise ValueError(
                f"episode {self.seed}: {len(self.steps)} steps but labels {self.labels.shape}"
            )


def filter_episode(episode: Episode, params: DSTParams) -> np.ndarray:
    """Run the DST filter over an episode.

    Returns:
        ``(K, 10, H, W) float32``: BetP at each scored step t and at t-1 (BetP at t
        again on step 0), the layout of :meth:`dstenv.frame.Frame.fcn_input`.
    """
    from dstenv.dst.tracker import GridTracker

    h, w = episode.sensor.shape[1:]
    tracker = GridTracker((h, w), params, cell_size=episode.cell_size)
    out = np.empty((len(episode.steps), 10, h, w), dtype=np.float32)
    wanted = {int(s): k for k, s in enumerate(episode.steps)}
    last = int(episode.steps[-1]) if len(episode.steps) else -1
    for t in range(last + 1):
        step = tracker.step(episode.sensor[t], episode.gis[t], episode.poses[t])
        if t in wanted:
            out[wanted[t], :5] = step.betp
            out[wanted[t], 5:] = step.betp_prev
    return out


def record_episodes(
    config: Mapping[str, Any],
    targets: Mapping[int, Sequence[int]],
    progress: bool = False,
) -> list[Episode]:
    """Replay episodes with :class:`dstenv.pipeline.Pipeline` and keep their raw inputs.

    Args:
        config: the full pipeline configuration the shards were generated with
            (their ``config`` attribute).
        targets: episode seed -> steps to score (labels and ``visible`` are kept there).
        progress: show a tqdm bar.

    Returns:
        One :class:`Episode` per seed, in ``sorted(targets)`` order.
    """
    from tqdm import tqdm

    from dstenv.pipeline import Pipeline

    if filter_period(config) != 1:
        raise ValueError(
            f"record_episodes: the shards fused every {filter_period(config)} steps "
            "(protocol.update_every); replay re-fuses every step, so it cannot reproduce "
            "them: generate with protocol.update_every = 1 to tune or re-score DST variants"
        )
    pipe = Pipeline(dict(config))
    episodes = []
    for seed in tqdm(sorted(targets), desc="replay episodes", disable=not progress, leave=False):
        steps = np.array(sorted(set(int(s) for s in targets[seed])), dtype=np.int64)
        frames = [pipe.reset(seed=int(seed))]
        while len(frames) <= steps[-1]:
            frames.append(pipe.step())
        episodes.append(
            Episode(
                seed=int(seed),
                sensor=np.stack([f.sensor for f in frames]),
                gis=np.stack([f.gis for f in frames]),
                poses=np.stack([np.asarray(f.ego_pose, dtype=np.float64) for f in frames]),
                steps=steps,
                labels=np.stack([frames[s].labels for s in steps]),
                visible=np.stack([frames[s].visible for s in steps]),
                cell_size=float(config["grid"]["cell_size"]),
            )
        )
    return episodes


def check_replay(
    episode: Episode,
    stored_x: np.ndarray,
    stored_labels: np.ndarray,
    params: DSTParams,
    atol: float = 1.0 / 255.0,
) -> None:
    """Raise if the replay does not reproduce the stored frames.

    Args:
        episode: a recorded episode.
        stored_x: ``(K, 10, H, W)`` BetP t / t-1 read from the shards at ``episode.steps``.
        stored_labels: ``(K, H, W)`` stored labels.
        params: the generation parameters.
        atol: tolerance (uint8-quantised shards are within 1/510 of the truth).

    Raises:
        RuntimeError: naming the episode and the largest difference.
    """
    if not np.array_equal(episode.labels, np.asarray(stored_labels, dtype=episode.labels.dtype)):
        raise RuntimeError(
            f"replay of episode seed {episode.seed} gives other labels than the shard: "
            "the pipeline is not reproducible with the stored config"
        )
    diff = (
        float(np.abs(filter_episode(episode, params) - stored_x).max())
        if len(episode.steps)
        else 0.0
    )
    if diff > atol:
        raise RuntimeError(
            f"replay of episode seed {episode.seed} differs from the stored BetP by {diff:.4f} "
            f"(> {atol:.4f}) with the generation DST parameters"
        )


def split_index(files: list[Path]) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Frames of a list of shards (e.g. ``ShardDataset.files``) with their origin.

    Returns:
        ``(frames, config)``: ``frames`` lists ``{"file", "index", "seed", "step",
        "moving"}`` in dataset order (entry k is ``ShardDataset[k]``); ``config`` is
        the pipeline configuration the shards were generated with.

    Raises:
        FileNotFoundError: no shard.
        ValueError: shards made with different configurations.
    """
    from dstenv.data.shards import ShardReader

    if not files:
        raise FileNotFoundError("no shards for this split (run dstenv generate first)")
    frames, config = [], None
    for f in files:
        with ShardReader(f) as r:
            if config is None:
                config = r.attrs["config"]
            elif r.attrs["config"] != config:
                raise ValueError(f"{f}: generated with another configuration than {files[0]}")
            for i in range(len(r)):
                d = r.get(i, ["seed", "step", "class_counts"])
                frames.append(
                    {
                        "file": str(f),
                        "index": i,
                        "seed": int(d["seed"]),
                        "step": int(d["step"]),
                        "moving": int(d["class_counts"][CLASSES.index("moving")]),
                    }
                )
    return frames, config


def episode_targets(
    frames: list[dict[str, Any]], max_episodes: int | None = None
) -> dict[int, list[int]]:
    """Episode seed -> stored steps, from :func:`split_index` frames.

    Args:
        frames: as returned by :func:`split_index`.
        max_episodes: keep only the first this many episodes (in frame order).
    """
    targets: dict[int, list[int]] = {}
    for fr in frames:
        if fr["seed"] not in targets and max_episodes is not None and len(targets) >= max_episodes:
            continue
        targets.setdefault(fr["seed"], []).append(fr["step"])
    return targets


def stored_inputs(
    frames: list[dict[str, Any]], seed: int, steps: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Stored ``(K, 10, H, W) float32`` BetP t/t-1 and ``(K, H, W) uint8`` labels of an episode."""
    from dstenv.data.shards import ShardReader

    by_step = {fr["step"]: fr for fr in frames if fr["seed"] == seed}
    xs, labs = [], []
    for s in steps:
        fr = by_step[int(s)]
        with ShardReader(fr["file"]) as r:
            d = r.get(fr["index"], ["pignistic", "pignistic_prev", "labels"])
        xs.append(np.concatenate([d["pignistic"], d["pignistic_prev"]]))
        labs.append(d["labels"])
    return np.stack(xs), np.stack(labs)


def filter_period(config: Mapping[str, Any]) -> int:
    """Steps between two DST updates of a shard's producer.

    ``update_every`` of a KITTI conversion (:func:`dstenv.kitti.sequence.default_config`)
    or ``protocol.update_every`` of the simulator (default 1: every step).
    """
    protocol = config.get("protocol", {})  # simulated shards: protocol.update_every
    return int(config.get("update_every", protocol.get("update_every", 1)))


def stored_episodes(
    frames: list[dict[str, Any]], config: Mapping[str, Any]
) -> tuple[list[tuple[Episode, np.ndarray]], str | None]:
    """Episodes rebuilt from the stored inputs, if the shards hold every filtered step.

    Args:
        frames: as returned by :func:`split_index`.
        config: the shards' configuration (its ``grid.cell_size`` and
            :func:`filter_period` are used).

    Returns:
        ``(episodes, None)``: per episode seed (sorted), an :class:`Episode` whose
        time axis is the stored frames (``steps = arange(K)``) and the ``(K,) int64``
        stored step numbers; or ``([], reason)`` when some episode's stored steps are
        not ``0, p, 2p, ...`` (``p`` = :func:`filter_period`), naming it.
    """
    from dstenv.data.shards import ShardReader

    period = filter_period(config)
    by_seed: dict[int, list[dict[str, Any]]] = {}
    for fr in frames:
        by_seed.setdefault(fr["seed"], []).append(fr)
    for seed in sorted(by_seed):
        steps = np.array(sorted(fr["step"] for fr in by_seed[seed]), dtype=np.int64)
        if not np.array_equal(steps, period * np.arange(len(steps))):
            return [], (
                f"episode {seed} stores steps {', '.join(map(str, steps[:4]))}"
                f"{', ...' if len(steps) > 4 else ''} but the DST filter ran on every "
                f"{period} step(s) from 0: the filter state between stored frames is lost "
                "(store every filtered frame, e.g. kitti convert --stride 1 --warmup 0)"
            )
    episodes = []
    names = ["sensor", "gis", "ego_pose", "labels", "visible"]
    for seed in sorted(by_seed):
        rows = sorted(by_seed[seed], key=lambda fr: fr["step"])
        got: dict[str, list[np.ndarray]] = {n: [] for n in names}
        for fr in rows:
            with ShardReader(fr["file"]) as r:
                d = r.get(fr["index"], names)
            for n in names:
                got[n].append(np.asarray(d[n]))
        ep = Episode(
            seed=int(seed),
            sensor=np.stack(got["sensor"]).astype(np.uint8),
            gis=np.stack(got["gis"]).astype(np.uint8),
            poses=np.stack(got["ego_pose"]).astype(np.float64),
            steps=np.arange(len(rows), dtype=np.int64),
            labels=np.stack(got["labels"]).astype(np.uint8),
            visible=np.stack(got["visible"]).astype(bool),
            cell_size=float(config["grid"]["cell_size"]),
        )
        episodes.append((ep, np.array([fr["step"] for fr in rows], dtype=np.int64)))
    return episodes, None


def shard_attrs(files: list[Path]) -> dict[str, Any]:
    """Root attributes of the first shard (``source``, ``config``, ``cell_size``...)."""
    from dstenv.data.shards import ShardReader

    if not files:
        raise FileNotFoundError("no shards for this split")
    with ShardReader(files[0]) as r:
        return dict(r.attrs)
