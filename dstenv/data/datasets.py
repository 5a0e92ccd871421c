"""PyTorch datasets: stored shards (:class:`ShardDataset`) and endless simulation
(:class:`StreamingDataset`).

Both yield ``{"x": (C, H, W) float32, "labels": (H, W) int64, "visible": (H, W) bool}``
tensors. ``inputs`` selects ``x``:

* ``"fcn10"``: the paper's FCN input, BetP at t then at t-1 (C = 10);
* ``"pignistic"``: BetP at t (C = 5);
* ``"masses"``: the raw DST masses (C = 32; shards generated with ``--masses``);
* ``"fcn10+sensor"``: ``fcn10`` then the current sensor grid as two 0/1 channels, seen
  free and seen occupied (C = 12; :func:`sensor_channels`): what the LIDAR says now,
  which the filter's BetP carries only after its inertia.
* ``"fcn10+sensor+past"``: ``fcn10+sensor`` then the sensor grid of :data:`PAST_STEPS`
  steps earlier (one second), moved into the ego frame of t by the filter's
  nearest-cell warp, as two more 0/1 channels (C = 14; :func:`past_sensor`): a static
  object's cells were occupied there too, a moving one's were seen free
  (``docs/past_occupancy.py``: alike on KITTI and in the simulator). Read from the
  drive's stored frames (the frame ``PAST_STEPS`` steps earlier of the same drive;
  unknown where there is none), so not from a :class:`StreamingDataset`.

Labels keep :data:`dstenv.frame.IGNORE_INDEX` (255) for excluded cells. ``labels``
selects their convention: ``"full"`` (as stored) or ``"kitti"``, KITTI's own
(:func:`dstenv.kitti.grids.kitti_convention`: objects everywhere, seen-free cells
navigable, everything else ignored), to train for real drives labelled that way.
"""

from __future__ import annotations

import bisect
import math
import numbers
import operator
import os
import warnings
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch.utils.data import Dataset, IterableDataset, get_worker_info

from dstenv.data.manifest import MANIFEST_NAME, UNSPLIT, one_dataset, scan_shards
from dstenv.data.sampling import (SPLITS, episode_seeds, frame_steps, iter_frames,
                                   scenario_config)
from dstenv.data.shardfiles import resolve_files, same_dataset
from dstenv.data.shards import N_CLASSES, ShardError, ShardReader
from dstenv.data.inputs import (
    INPUT_CHANNELS,
    INPUTS,
    LABELS,
    PAST_STEPS,
    _check_inputs,
    _check_labels,
    network_input,
    past_rows,
    past_sensor,
    sensor_channels,
)
from dstenv.frame import Frame

__all__ = ["INPUTS", "INPUT_CHANNELS", "LABELS", "PAST_STEPS", "ShardDataset",
           "StreamingDataset", "frame_to_sample", "sensor_channels", "network_input",
           "past_sensor", "past_rows"]

def _sample(arrays: Mapping[str, np.ndarray], names: Sequence[str],
            labels: str = "full") -> dict[str, torch.Tensor]:
    x = np.concatenate([sensor_channels(arrays[n]) if n in ("sensor", "past")
                        else np.asarray(arrays[n], dtype=np.float32) for n in names], axis=0)
    lab = arrays["labels"]
    if labels == "kitti":
        from dstenv.kitti.grids import kitti_convention

        lab = kitti_convention(lab, arrays["sensor"])
    return {
        "x": torch.from_numpy(np.ascontiguousarray(x)),
        "labels": torch.from_numpy(np.asarray(lab, dtype=np.int64)),
        "visible": torch.from_numpy(np.asarray(arrays["visible"], dtype=bool)),
    }


def frame_to_sample(frame: Frame, inputs: str = "fcn10", labels: str = "full"
                    ) -> dict[str, torch.Tensor]:
    """A :class:`Frame` as a training sample (see the module docstring)."""
    names = _check_inputs(inputs, single_frames=True)
    if inputs == "masses" and frame.masses is None:
        raise ValueError("inputs='masses' needs frames with masses (config frame.masses = true)")
    return _sample({n: getattr(frame, n) for n in (*names, "labels", "visible", "sensor")},
                   names, _check_labels(labels))


class ShardDataset(Dataset):
    """Map-style dataset over shard files (random access; safe with DataLoader workers).

    Args:
        root_or_files: a dataset directory (its ``manifest.json`` is checked when
            present, else ``*.h5`` files are scanned), one shard file, or a list of files.
        split: keep only shards of this split (``attrs["split"]``); ``None`` keeps all.
        inputs: a key of :data:`INPUTS` (module docstring).
        labels: ``"full"`` or ``"kitti"`` (module docstring); :attr:`class_counts`
            counts the stored labels either way.
        on_error: ``"raise"``: a corrupt or truncated shard raises
            :class:`~dstenv.data.shards.ShardError` naming the file; ``"skip"``: it is
            left out with a warning naming it (at construction, or at the first failed
            read, when the next readable frame is returned instead).
        cache: keep every frame read, as stored (uint8 probabilities: about
            ``(2 C + 2) H W`` bytes a frame, 0.2 MB at 128 x 128 with ``fcn10``), so
            later epochs skip HDF5 decompression; each DataLoader worker keeps its own.

    Files are opened lazily in each process (h5py handles are never shared across a
    fork), so ``DataLoader(num_workers=K)`` works with any start method.
    """

    def __init__(self, root_or_files: str | Path | Sequence[str | Path], split: str | None = None,
                 inputs: str = "fcn10", on_error: str = "raise", cache: bool = False,
                 labels: str = "full") -> None:
        self.names = _check_inputs(inputs)
        self.labels = _check_labels(labels)
        if on_error not in ("raise", "skip"):
            raise ValueError(f"on_error must be 'raise' or 'skip', got {on_error!r}")
        if not isinstance(cache, (bool, np.bool_)):  # ("yes" and "no" were both True)
            raise TypeError(f"ShardDataset cache must be True or False, got {cache!r}")
        self.inputs, self.on_error, self.split = inputs, on_error, split
        self.files: list[Path] = []
        self._stamps: list[tuple[int, ...]] = []  # each file as it was read here
        lengths: list[int] = []
        #: ``(5,) int64`` labelled cells per class over the kept shards (loss weights)
        self.class_counts = np.zeros(N_CLASSES, dtype=np.int64)
        folder = isinstance(root_or_files, (str, Path)) and Path(root_or_files).is_dir()
        first: tuple[Path, Any, Any] | None = None  # path, geometry, config
        # generate and kitti convert write manifest.json last: without it, their run died
        if unfinished := folder and not (Path(root_or_files) / MANIFEST_NAME).is_file():
            one_dataset(root_or_files)  # (unless it holds finished datasets: not one)
        for path, _ in resolve_files(root_or_files, split):
            try:
                with ShardReader(path) as r:
                    if unfinished and (r.attrs.get("source") == "kitti" or "task" in r.attrs):
                        made = "kitti convert" if "task" not in r.attrs else "generate"
                        raise ValueError(
                            f"{root_or_files}: no {MANIFEST_NAME}, but its shards come from "
                            f"dstenv {made}, which writes it last: that run did not finish; "
                            "rerun its command to complete the folder (or pass shard files)")
                    if split is not None and r.attrs.get("split") != split:
                        continue
                    if inputs == "masses" and not r.has_masses:
                        raise ShardError(f"{path}: inputs='masses' but the shard has no masses "
                                         "(generate with --masses)")
                    n = len(r)
                    counts = r.class_counts()
                    mine = (path, (tuple(r.grid_shape), float(r.cell_size)),
                            r.attrs.get("config"))
            except ShardError as exc:
                self._fail(exc)
                continue
            first = first or mine
            same_dataset(first, mine, folder)
            self.files.append(path)
            self._stamps.append(_stamp(path))
            lengths.append(n)
            self.class_counts += counts
        #: ``(H, W)`` cells and cell size [m] of the kept shards (``None`` without any)
        self.grid_shape, self.cell_size = first[1] if first else (None, None)
        if not self.files and split is not None and split not in (*SPLITS, UNSPLIT):
            # a known split may be absent (no val split); an unknown one is a typo
            there = sorted({p.parent.name for p in scan_shards(root_or_files)} if folder else [])
            raise ValueError(f"no shard of split {split!r} in {root_or_files} (its splits: "
                             f"{', '.join(there) or 'none'})")
        self._ends = np.cumsum(lengths).tolist()
        self._bad: set[int] = set()
        self._readers: dict[int, ShardReader] = {}
        self._pid = os.getpid()
        self.cache = bool(cache)
        self._cache: dict[int, tuple[int, dict[str, np.ndarray]]] = {}
        # fcn10+sensor+past: per shard, the frame PAST_STEPS steps before each (or -1)
        self._past: dict[int, np.ndarray] = {}
        if "past" in inputs:
            self._check_past(root_or_files, inputs)

    def _check_past(self, where: Any, inputs: str) -> None:
        """Refuse frames stored at a stride that never reaches the frame ``PAST_STEPS``
        earlier (drives too short to hold one are fine); each shard's steps read once."""
        gaps: set[int] = set()
        for k in range(len(self.files)):
            steps = self._steps(k)
            self._past[k] = past_rows(steps)
            if (self._past[k] >= 0).any():
                return
            gaps |= {int(g) for g in np.diff(steps) if g > 0}
        if gaps and PAST_STEPS % math.gcd(*gaps):
            raise ValueError(
                f"{where}: inputs {inputs!r} read the frame {PAST_STEPS} steps before each, "
                f"but no stored frame has one (frames {'/'.join(map(str, sorted(gaps)))} "
                f"steps apart): store frames at a stride that divides {PAST_STEPS} "
                "(--stride), or use fcn10+sensor")

    def _steps(self, k: int) -> np.ndarray:
        r = self._reader(k)
        return np.array([int(r.get(i, ("step",))["step"]) for i in range(len(r))], np.int64)

    def _pasts(self, k: int) -> np.ndarray:
        if k not in self._past:
            self._past[k] = past_rows(self._steps(k))
        return self._past[k]

    def _past_row(self, k: int, local: int) -> int:
        return int(self._pasts(k)[local])

    def _fail(self, exc: ShardError) -> None:
        if self.on_error == "raise":
            raise exc
        warnings.warn(f"skipping corrupt shard: {exc}", RuntimeWarning, stacklevel=3)

    def __len__(self) -> int:
        return self._ends[-1] if self._ends else 0

    def _reader(self, k: int) -> ShardReader:
        if self._pid != os.getpid():  # forked into a worker: never reuse the parent's handles
            self._readers, self._pid = {}, os.getpid()
        if k not in self._readers:
            reader = ShardReader(self.files[k])
            if _stamp(self.files[k]) != self._stamps[k]:  # (replaced under a running train,
                reader.close()  # its frames were read as if they were the ones counted)
                raise ShardError(f"{self.files[k]}: changed since this dataset was opened "
                                 "(another run rewrote it?); open the dataset again")
            self._readers[k] = reader
        return self._readers[k]

    def no_map_indices(self) -> list[int]:
        """Indices of the frames fused without a map: their stored GIS grid is all
        ``MapClass.NONE`` (drives of ``gis.source = "none"`` or ``gis.no_map_prob``)."""
        out, start = [], 0
        for k, end in enumerate(self._ends):
            reader = self._reader(k)
            out += [start + i for i in range(end - start)
                    if not reader.get(i, ("gis",))["gis"].any()]
            start = end
        return out

    def _index(self, index: Any) -> int:
        """``index`` as an int in ``[0, len)``: any integer (numpy, a 0-d torch integer
        tensor), negative ones from the end, like a list."""
        n = len(self)
        try:
            if isinstance(index, bool):
                raise TypeError
            i = operator.index(index)
        except TypeError:
            raise TypeError(f"ShardDataset index must be an integer, got {index!r}") from None
        if not -n <= i < n:  # IndexError ends a plain `for sample in dataset` loop
            raise IndexError(f"ShardDataset index {i} out of range for {n} frames")
        return i % n

    def locate(self, index: int) -> tuple[Path, int]:
        """``(shard file, frame index inside it)`` of a dataset index (negative: from
        the end)."""
        index = self._index(index)
        k = bisect.bisect_right(self._ends, index)
        return self.files[k], index - (self._ends[k - 1] if k else 0)

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        index, n = self._index(index), len(self)
        for attempt in range(n):  # a corrupt shard skipped (on_error="skip"): the next frame
            i = (index + attempt) % n
            k = bisect.bisect_right(self._ends, i)
            if k in self._bad:
                continue
            local = i - (self._ends[k - 1] if k else 0)
            try:
                if i in self._cache:
                    k, arrays = self._cache[i]
                else:
                    wanted = {*self.names, "labels", "visible"} - {"past"}
                    if self.labels == "kitti":
                        wanted.add("sensor")
                    if "past" in self.names:
                        wanted |= {"sensor", "ego_pose"}
                    arrays = self._reader(k).get(local, sorted(wanted), stored=True)
                    if "past" in self.names:
                        arrays = dict(arrays, past=self._read_past(k, local, arrays["sensor"],
                                                                   arrays["ego_pose"]))
                    if self.cache:
                        self._cache[i] = (k, arrays)
            except ShardError as exc:
                self._fail(exc)
                self._bad.add(k)
                continue
            reader = self._reader(k)
            return _sample({n: reader.dequantise(n, a) for n, a in arrays.items()}, self.names,
                           self.labels)
        raise ShardError(f"no readable frame left in {len(self.files)} shards")

    def _read_past(self, k: int, local: int, sensor: np.ndarray, pose: np.ndarray
                   ) -> np.ndarray:
        """The sensor grid :data:`PAST_STEPS` steps before frame ``local`` of shard
        ``k`` (whose ``sensor`` and ego ``pose`` are given), in its ego frame (all
        unknown when the shard has no such frame)."""
        j = self._past_row(k, local)
        if j < 0:
            return np.zeros_like(sensor)
        r = self._reader(k)
        prev = r.get(j, ("sensor", "ego_pose"))
        return past_sensor(prev["sensor"], prev["ego_pose"], pose, r.cell_size)

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state["_readers"] = {}  # open h5py files do not pickle (spawned workers)
        state["_cache"] = {}
        return state

    def __del__(self) -> None:
        for r in getattr(self, "_readers", {}).values():
            try:
                r.close()
            except Exception:  # noqa: BLE001 - interpreter shutdown
                pass


class StreamingDataset(IterableDataset):
    """Endless frames simulated inside each DataLoader worker: training without disk.

    Args:
        scenario: scenario name or ``.toml`` path, a config dict (overrides of
            :func:`dstenv.pipeline.default_config`), or ``None`` for the defaults.
        seed: base seed. Worker ``w`` of rank ``r`` at epoch ``e`` draws its episodes
            from the stream ``(r, w, e)``, so workers never repeat each other.
        split: episodes come only from this split's map seeds (default ``"train"``:
            test maps stay unseen); ``None`` for any.
        inputs: a key of :data:`INPUTS`; labels: ``"full"`` or ``"kitti"``.
        episode_length, stride, warmup: as in ``dstenv generate`` (steps of 0.1 s).
        episodes_per_map: episodes on each procedural city before the next one
            (:mod:`dstenv.data.sampling`; 1: a new city per episode).
        max_frames: stop each worker after this many frames (``None``: forever); a
            ``DataLoader`` of W workers then yields ``W * max_frames`` per rank.
        rank: process rank for distributed training.
    """

    def __init__(self, scenario: str | Path | Mapping[str, Any] | None = None, seed: int = 0, *,
                 split: str | None = "train", inputs: str = "fcn10", episode_length: int = 200,
                 stride: int = 10, warmup: int | None = None, max_frames: int | None = None,
                 rank: int = 0, episodes_per_map: int = 1, labels: str = "full") -> None:
        super().__init__()
        self.labels = _check_labels(labels)
        self.config = scenario_config(scenario)
        self.names = _check_inputs(inputs, single_frames=True)
        if inputs == "masses":
            self.config["frame"]["masses"] = True
        for name, v, low in (("seed", seed, 0), ("rank", rank, 0)):
            if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < low:
                raise ValueError(f"StreamingDataset {name} must be an integer >= {low}, got "
                                 f"{v!r}")
        if max_frames is not None and (not isinstance(max_frames, (int, np.integer))
                                       or isinstance(max_frames, bool) or max_frames < 1):
            raise ValueError(f"StreamingDataset max_frames must be None or an integer >= 1, "
                             f"got {max_frames!r}")
        self.inputs, self.seed, self.split, self.rank = inputs, int(seed), split, int(rank)
        self.episode_length, self.stride = episode_length, stride
        self.warmup = stride if warmup is None else warmup
        self.max_frames = max_frames
        if episodes_per_map < 1:
            raise ValueError(f"episodes per map must be >= 1, got {episodes_per_map}")
        self.episodes_per_map = int(episodes_per_map)
        self.epoch = 0
        next(episode_seeds(self.seed, split, ()))  # validates the split name early (a generator)
        frame_steps(int(episode_length), int(stride), int(self.warmup))  # and the steps

    def set_epoch(self, epoch: int) -> None:
        """Use another episode stream for this epoch (like ``DistributedSampler``).

        Call it before each epoch's iteration, with ``DataLoader(persistent_workers=False)``
        (the default): persistent workers keep the copy of the dataset they started with,
        so a new epoch never reaches them (make a new ``DataLoader`` per epoch instead)."""
        if not isinstance(epoch, numbers.Integral) or isinstance(epoch, bool) or epoch < 0:
            raise ValueError(f"set_epoch: an integer >= 0, got {epoch!r}")  # (1.7 was 1)
        self.epoch = int(epoch)

    def __iter__(self) -> Iterator[dict[str, torch.Tensor]]:
        from dstenv.pipeline import Pipeline

        info = get_worker_info()
        worker = 0 if info is None else info.id
        seeds = episode_seeds(self.seed, self.split, (self.rank, worker, self.epoch))
        frames = iter_frames(lambda: Pipeline(self.config), seeds, self.episode_length,
                             self.stride, self.warmup, self.episodes_per_map)
        for n, frame in enumerate(frames):
            if self.max_frames is not None and n >= self.max_frames:
                return
            yield frame_to_sample(frame, self.inputs, self.labels)


def _stamp(path: Path) -> tuple[int, ...]:
    """A file's identity on disk: device, inode, size, modification time [ns]."""
    st = os.stat(path)
    return st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns
