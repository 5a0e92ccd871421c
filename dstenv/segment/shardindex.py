"""The frames of a shard split and the drives they come from (:mod:`dstenv.segment`).

:func:`split_index` lists a split's frames with their drive ``(seed, episode)``;
:func:`episode_targets` and :func:`stored_inputs` give a drive's stored steps and
stored inputs; :func:`stored_episodes` rebuilds
:class:`~dstenv.segment.replay.Episode` objects of evaluation-only data (KITTI
conversions) from the stored per-frame inputs, honestly only when every filtered step
is stored; :func:`shard_attrs` reads a split's root attributes.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from dstenv.dst.frame import CLASSES
from dstenv.segment.replay import Episode, filter_period
from dstenv.sensing.odometry import ODOMETRY_KEYS

__all__ = [
    "split_index",
    "episode_targets",
    "stored_inputs",
    "stored_episodes",
    "shard_attrs",
]


def split_index(files: list[Path]) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Frames of a list of shards (e.g. ``ShardDataset.files``) with their origin.

    A frame's drive is ``(seed, episode)``: with several episodes per map
    (:mod:`dstenv.data.sampling`) the step restarts at every episode of one map seed,
    so ``episode`` counts those restarts within a shard (episodes never span shards).

    Returns:
        ``(frames, config)``: ``frames`` lists ``{"file", "index", "seed", "episode",
        "step", "moving"}`` in dataset order (entry k is ``ShardDataset[k]``);
        ``config`` is the pipeline configuration the shards were generated with.

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
            last: tuple[int, int] | None = None  # (seed, step) of the previous frame
            episode = 0
            for i in range(len(r)):
                d = r.get(i, ["seed", "step", "class_counts"])
                seed, step = int(d["seed"]), int(d["step"])
                if last is not None and last[0] == seed and step <= last[1]:
                    episode += 1
                elif last is not None and last[0] != seed:
                    episode = 0
                last = (seed, step)
                frames.append(
                    {
                        "file": str(f),
                        "index": i,
                        "seed": seed,
                        "episode": episode,
                        "step": step,
                        "moving": int(d["class_counts"][CLASSES.index("moving")]),
                    }
                )
    return frames, config


def episode_targets(
    frames: list[dict[str, Any]], max_episodes: int | None = None
) -> dict[tuple[int, int], list[int]]:
    """``(seed, episode)`` -> stored steps, from :func:`split_index` frames.

    Args:
        frames: as returned by :func:`split_index`.
        max_episodes: keep only the first this many episodes (in frame order).
    """
    targets: dict[tuple[int, int], list[int]] = {}
    for fr in frames:
        key = (fr["seed"], fr["episode"])
        if key not in targets and max_episodes is not None and len(targets) >= max_episodes:
            continue
        targets.setdefault(key, []).append(fr["step"])
    return targets


def stored_inputs(
    frames: list[dict[str, Any]], key: tuple[int, int], steps: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Stored ``(K, 10, H, W) float32`` BetP t/t-1 and ``(K, H, W) uint8`` labels of a drive.

    Args:
        frames: as returned by :func:`split_index`.
        key: the drive ``(seed, episode)``.
        steps: ``(K,)`` stored steps of that drive.
    """
    from dstenv.data.shards import ShardReader

    by_step = {fr["step"]: fr for fr in frames if (fr["seed"], fr["episode"]) == tuple(key)}
    xs, labs = [], []
    for s in steps:
        fr = by_step[int(s)]
        with ShardReader(fr["file"]) as r:
            d = r.get(fr["index"], ["pignistic", "pignistic_prev", "labels"])
        xs.append(np.concatenate([d["pignistic"], d["pignistic_prev"]]))
        labs.append(d["labels"])
    return np.stack(xs).astype(np.float32), np.stack(labs)


def stored_episodes(
    frames: list[dict[str, Any]], config: Mapping[str, Any], require_history: bool = True
) -> tuple[list[tuple[Episode, np.ndarray]], str | None]:
    """Episodes rebuilt from the stored frames of evaluation-only data.

    Args:
        frames: as returned by :func:`split_index`.
        config: the shards' configuration (its ``grid.cell_size`` and
            :func:`filter_period` are used).
        require_history: when some drive's stored steps are not ``0, p, 2p, ...``
            (``p`` = :func:`filter_period`), return ``([], reason)`` if true; if false,
            return episodes of the stored frames only (``history=False``: scorable
            from their stored BetP, not re-filterable) and the reason.

    Returns:
        ``(episodes, reason)``: per drive ``(seed, episode)`` (sorted), an
        :class:`Episode` whose time axis is the stored frames (``steps = arange(K)``,
        ``stored_x`` set) and the ``(K,) int64`` stored step numbers; ``reason`` is
        ``None`` when every drive holds every filtered step, else why not.
    """
    from dstenv.data.shards import ShardReader

    period = filter_period(config)
    by_key: dict[tuple[int, int], list[dict[str, Any]]] = {}
    for fr in frames:
        by_key.setdefault((fr["seed"], fr["episode"]), []).append(fr)
    reason = None
    for key in sorted(by_key):
        steps = np.array(sorted(fr["step"] for fr in by_key[key]), dtype=np.int64)
        if not np.array_equal(steps, period * np.arange(len(steps))):
            reason = (
                f"episode {key[0]} stores steps {', '.join(map(str, steps[:4]))}"
                f"{', ...' if len(steps) > 4 else ''} but the DST filter ran on every "
                f"{period} step(s) from 0: the filter state between stored frames is lost "
                "(store every filtered frame, e.g. kitti convert --stride 1 --warmup 0)"
            )
            break
    prot = config.get("protocol", {})
    if reason is None and any(prot.get(k, 0.0) for k in ODOMETRY_KEYS):
        reason = ("the DST filter ran on noisy odometry (protocol.odometry_*), and the "
                  "stored ego poses are the true ones: score it from its stored BetP, or "
                  "replay it through the simulator (a dataset with a train split)")
    if reason is not None and require_history:
        return [], reason
    episodes = []
    names = ["sensor", "gis", "ego_pose", "labels", "visible", "pignistic", "pignistic_prev"]
    for key in sorted(by_key):
        rows = sorted(by_key[key], key=lambda fr: fr["step"])
        got: dict[str, list[np.ndarray]] = {n: [] for n in names}
        for fr in rows:
            with ShardReader(fr["file"]) as r:
                d = r.get(fr["index"], names)
            for n in names:
                got[n].append(np.asarray(d[n]))
        ep = Episode(
            seed=int(key[0]),
            episode=int(key[1]),
            sensor=np.stack(got["sensor"]).astype(np.uint8),
            gis=np.stack(got["gis"]).astype(np.uint8),
            poses=np.stack(got["ego_pose"]).astype(np.float64),
            steps=np.arange(len(rows), dtype=np.int64),
            labels=np.stack(got["labels"]).astype(np.uint8),
            visible=np.stack(got["visible"]).astype(bool),
            cell_size=float(config["grid"]["cell_size"]),
            stored_x=np.concatenate(
                [np.stack(got["pignistic"]), np.stack(got["pignistic_prev"])], axis=1
            ).astype(np.float32),
            history=reason is None,
            period=1,  # the time axis is the stored (= fused) frames
            stored_steps=np.array([fr["step"] for fr in rows], dtype=np.int64),
            row_steps=np.array([fr["step"] for fr in rows], dtype=np.int64),
        )
        episodes.append((ep, ep.stored_steps))
    return episodes, reason


def shard_attrs(files: list[Path]) -> dict[str, Any]:
    """Root attributes of the first shard (``source``, ``config``, ``cell_size``...)."""
    from dstenv.data.shards import ShardReader

    if not files:
        raise FileNotFoundError("no shards for this split")
    with ShardReader(files[0]) as r:
        return dict(r.attrs)
