"""Streaming training data with the DST fusion on the GPU: simulate on CPU, fuse batched.

:class:`SensorStream` is an ``IterableDataset`` whose DataLoader workers each drive
``streams`` simulations in lockstep *without* a DST filter
(``Pipeline(fuse=False)``: world, LIDAR sweep, sensor and GIS grids, labels) and
yield one batch per simulation step. :func:`fuse_batches` consumes the loader in
the training process and fuses every worker's streams with one
:class:`~dstenv.dst.batched.BatchedGridFilter` on ``device`` (a GPU when there is
one), yielding the paper's samples (``x``: BetP at t and t-1, ``labels``,
``visible``) for the kept steps only (``stride``/``warmup`` as ``dstenv generate``).

The frames are those of :class:`~dstenv.data.StreamingDataset` with the same seeds
(BetP to float32 rounding, < 1e-5; labels identical): stream ``s`` of worker ``w``
of rank ``r`` draws its episodes from ``episode_seeds(seed, split, (r, w, s))``.

Example::

    loader = DataLoader(SensorStream("dense", seed=0, streams=8), batch_size=None,
                        num_workers=2)
    for batch in fuse_batches(loader, device="cuda"):
        loss = criterion(model(batch["x"]), batch["labels"])   # (K, 10, H, W) ...
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch.utils.data import IterableDataset, get_worker_info

from dstenv.data.sampling import episode_seeds, frame_steps, scenario_config
from dstenv.grid import relative_pose

__all__ = ["SensorStream", "fuse_batches"]


class SensorStream(IterableDataset):
    """Batches of the DST filter's inputs from ``streams`` lockstep simulations.

    Args:
        scenario: scenario name or ``.toml`` path, a config dict, or ``None``.
        seed: base seed (see the module docstring for the streams' seeds).
        streams: simulations per worker, stepped together (the batch size B).
        split: map seeds of this split only (default ``"train"``); ``None``: any.
        episode_length, stride, warmup: as in ``dstenv generate`` (steps of 0.1 s).
        rank: process rank for distributed training.

    Yields (one dict per step, tensors on the CPU): ``worker`` (int), ``sensor`` and
    ``gis`` ``(B, H, W) uint8``, ``fused`` (bool: a fused step of
    ``protocol.update_every``), ``motion`` ``(B, 3) float64`` (ego motion since the
    previous fused step, zeros on an episode's first step), ``start`` ``(B,) bool``
    (first step of an episode), ``keep`` ``(B,) bool`` (a stored step),
    ``labels`` ``(B, H, W) uint8`` and ``visible`` ``(B, H, W) bool``.
    """

    def __init__(self, scenario: str | Path | Mapping[str, Any] | None = None, seed: int = 0,
                 *, streams: int = 4, split: str | None = "train", episode_length: int = 200,
                 stride: int = 10, warmup: int | None = None, rank: int = 0) -> None:
        super().__init__()
        if streams < 1:
            raise ValueError(f"streams must be >= 1, got {streams}")
        self.config = scenario_config(scenario)
        self.seed, self.streams, self.split, self.rank = int(seed), int(streams), split, int(rank)
        self.episode_length = int(episode_length)
        self.update_every = int(self.config["protocol"]["update_every"])
        self.keep = set(frame_steps(self.episode_length, stride,
                                    stride if warmup is None else warmup))
        next(episode_seeds(self.seed, split, ()))  # validates the split name early

    def __iter__(self) -> Iterator[dict[str, Any]]:
        from dstenv.pipeline import Pipeline

        info = get_worker_info()
        worker = 0 if info is None else info.id
        seeds = [episode_seeds(self.seed, self.split, (self.rank, worker, s))
                 for s in range(self.streams)]
        pipes = [Pipeline(self.config, fuse=False) for _ in range(self.streams)]
        frames = [p.reset(next(sd)) for p, sd in zip(pipes, seeds)]
        prev = [None] * self.streams
        step = 0
        while True:
            fused = step % self.update_every == 0
            motion = np.zeros((self.streams, 3))
            for s, f in enumerate(frames):
                if fused:  # ego motion since the stream's previous fused step
                    if step > 0:
                        motion[s] = relative_pose(prev[s], f.ego_pose)
                    prev[s] = f.ego_pose
            yield {
                "fused": fused,
                "worker": worker,
                "sensor": torch.from_numpy(np.stack([f.sensor for f in frames])),
                "gis": torch.from_numpy(np.stack([f.gis for f in frames])),
                "motion": torch.from_numpy(motion),
                "start": torch.full((self.streams,), step == 0),
                "keep": torch.full((self.streams,), step in self.keep),
                "labels": torch.from_numpy(np.stack([f.labels for f in frames])),
                "visible": torch.from_numpy(np.stack([f.visible for f in frames])),
            }
            step += 1
            if step == self.episode_length:
                step = 0
                frames = [p.reset(next(sd)) for p, sd in zip(pipes, seeds)]
            else:
                frames = [p.step(None) for p in pipes]


def fuse_batches(batches: Iterable[Mapping[str, Any]], device: str | torch.device = "cpu",
                 config: Mapping[str, Any] | None = None) -> Iterator[dict[str, torch.Tensor]]:
    """Fuse :class:`SensorStream` batches with one batched filter per worker.

    Args:
        batches: a ``DataLoader(SensorStream(...), batch_size=None, ...)`` (or the
            dataset itself).
        device: where the filters run and the samples are returned.
        config: the stream's configuration (its ``grid`` and ``dst`` sections);
            default: taken from ``batches.dataset`` or ``batches``.

    Yields:
        ``{"x": (K, 10, H, W) float32, "labels": (K, H, W) int64, "visible": (K, H, W)
        bool}`` on ``device`` for the K streams whose step is kept (steps where none
        is kept yield nothing).
    """
    from dstenv.dst import DSTParams
    from dstenv.dst.batched import BatchedGridFilter

    if config is None:
        config = getattr(batches, "dataset", batches).config  # type: ignore[union-attr]
    grid, params = config["grid"], DSTParams.from_dict(config["dst"])
    filters: dict[int, BatchedGridFilter] = {}
    prev: dict[int, torch.Tensor] = {}
    last: dict[int, tuple[torch.Tensor, torch.Tensor]] = {}
    for b in batches:
        wid = int(b["worker"])
        sensor = b["sensor"].to(device)
        if wid not in filters:
            filters[wid] = BatchedGridFilter(sensor.shape[0], (grid["height"], grid["width"]),
                                             params, grid["cell_size"], device)
        f = filters[wid]
        start = b["start"].to(device)
        if bool(start.any()):
            f.reset(start)
        if bool(b.get("fused", True)) or wid not in last:
            betp = f.update(sensor, b["gis"].to(device), b["motion"].to(device))
            before = prev.get(wid, betp)
            # t-1 is the previous fused frame (the first frame of an episode: itself)
            before = torch.where(start[:, None, None, None], betp, before)
            prev[wid], last[wid] = betp, (betp, before)
        betp, before = last[wid]  # steps between fused ones carry the last fused BetP
        keep = b["keep"].to(device)
        if bool(keep.any()):
            yield {"x": torch.cat([betp, before], dim=1)[keep],
                   "labels": b["labels"].to(device)[keep].to(torch.int64),
                   "visible": b["visible"].to(device)[keep]}
