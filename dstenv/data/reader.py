"""Reading shards: :class:`ShardReader` (format in :mod:`dstenv.data.shards`)."""

from __future__ import annotations

import errno
import json
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from dstenv.data.format import (
    DERIVED_FIELDS, FORMAT, FRAME_FIELDS, N_CLASSES, N_MASSES, PROB_FIELDS, READ_VERSIONS,
    SCALAR_FIELDS, ShardError, derive, grid_fields, prob_shape, short_error,
)
from dstenv.dst.frame import CLASSES
from dstenv.frame import IGNORE_INDEX, Frame

__all__ = ["ShardReader"]


class ShardReader:
    """Random access to the frames of one shard, validated on open.

    Args:
        path: a shard file.

    Raises:
        ShardError: ``"<path>: <problem>"`` if the file is missing, not HDF5,
            truncated, of another format version, lacks a dataset, or has
            inconsistent shapes.

    Use as a context manager or call :meth:`close`. ``reader[i]`` is a :class:`Frame`
    (probabilities dequantised to float32); :meth:`get` reads selected arrays only.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise ShardError(f"{self.path}: no such shard file")
        try:
            # 16 MiB chunk cache: one 256x256 masses chunk is 8 MiB
            self._file = h5py.File(self.path, "r", rdcc_nbytes=16 << 20)
        except OSError as exc:
            if exc.errno == errno.EACCES or "errno = 13," in str(exc):  # not a corrupt file
                raise PermissionError(errno.EACCES, "permission denied; fix the file's "
                                      "permissions (it is not read as corrupt)",
                                      str(self.path)) from None
            raise ShardError(f"{self.path}: not a readable HDF5 file (truncated or corrupt?): "
                             f"{short_error(exc)}") from None
        try:
            self.attrs = self._read_attrs()
            self._validate()
        except ShardError:
            self._file.close()
            raise
        except (OSError, KeyError, ValueError, TypeError) as exc:
            self._file.close()
            raise ShardError(f"{self.path}: unreadable shard metadata: "
                             f"{short_error(exc)}") from None

    def _read_attrs(self) -> dict[str, Any]:
        raw = dict(self._file.attrs)
        if raw.get("format") != FORMAT:
            raise ShardError(f"{self.path}: not a dstenv shard "
                             f"(attribute format={raw.get('format')!r})")
        if int(raw.get("format_version", -1)) not in READ_VERSIONS:
            raise ShardError(f"{self.path}: shard format_version {raw.get('format_version')} is "
                             f"not supported (this dstenv reads "
                             f"{', '.join(map(str, READ_VERSIONS))})")
        out: dict[str, Any] = {}
        json_keys = set(json.loads(raw.pop("json_attrs", "[]")))
        for key, value in raw.items():
            if key in json_keys:
                out[key] = json.loads(value)
            elif isinstance(value, np.ndarray):
                out[key] = value.tolist()
            elif isinstance(value, np.generic):
                out[key] = value.item()
            else:
                out[key] = value
        return out

    def _validate(self) -> None:
        a = self.attrs
        for key in ("n_frames", "grid_shape", "prob_scale", "classes", "cell_size", "complete"):
            if key not in a:
                raise ShardError(f"{self.path}: attribute {key!r} missing")
        if not a["complete"]:
            raise ShardError(f"{self.path}: shard marked incomplete")
        n = int(a["n_frames"])
        h, w = (int(v) for v in a["grid_shape"])
        self.format_version = int(a["format_version"])
        expected = {
            **{k: (n, *prob_shape(self.format_version, h, w)) for k in PROB_FIELDS},
            **{k: (n, h, w) for k in grid_fields(self.format_version)},
            "ego_pose": (n, 3), **{k: (n,) for k in SCALAR_FIELDS},
            "class_counts": (n, N_CLASSES),
        }
        if a.get("has_masses"):
            expected["masses"] = (n, N_MASSES, h, w)
        for name, shape in expected.items():
            if name not in self._file:
                raise ShardError(f"{self.path}: dataset {name!r} missing")
            got = self._file[name].shape
            if got != shape:
                raise ShardError(f"{self.path}: dataset {name!r} has shape {got}, expected {shape}")
        # values a writer never makes: decoded they gave NaN inputs, or classes out of order
        for key in ("cell_size", "prob_scale"):
            if not (isinstance(a[key], (int, float)) and np.isfinite(a[key]) and a[key] > 0):
                raise ShardError(f"{self.path}: attribute {key!r} is {a[key]!r}, not a "
                                 "number > 0: not a shard as dstenv writes it")
        if list(a["classes"]) != list(CLASSES):
            raise ShardError(f"{self.path}: attribute 'classes' is {a['classes']!r}, not "
                             f"{list(CLASSES)}: not a shard as dstenv writes it")
        self.n_frames = n
        self.grid_shape: tuple[int, int] = (h, w)
        self.cell_size = float(a["cell_size"])
        self.classes: tuple[str, ...] = tuple(a["classes"])
        self.has_masses = bool(a.get("has_masses"))
        #: stored probability = round(p * prob_scale) (uint8 shards) or p (1.0, float32)
        self.prob_scale = float(a["prob_scale"])

    def __len__(self) -> int:
        return self.n_frames

    def get(self, index: int, names: Iterable[str], stored: bool = False) -> dict[str, np.ndarray]:
        """Read selected arrays of frame ``index``.

        Args:
            index: frame index, ``-len <= index < len``.
            names: dataset names (see the module table); probabilities come back as
                ``float32`` in [0, 1] whatever the stored dtype.
            stored: return probabilities as stored (``uint8`` scaled by
                :attr:`prob_scale`, or ``float32``) instead; see :meth:`dequantise`.
                Either way they are ``(5, H, W)`` (of format version 2, which stores
                them cell-major, a transposed view).

        Raises:
            IndexError: index out of range.
            ShardError: a chunk fails its checksum or cannot be read.
        """
        if not -self.n_frames <= index < self.n_frames:
            raise IndexError(f"{self.path}: frame {index} out of range (0..{self.n_frames - 1})")
        index %= self.n_frames
        if not self._file:
            raise ValueError(f"{self.path}: reader is closed")
        out: dict[str, np.ndarray] = {}
        names = [names] if isinstance(names, str) else list(names)  # ("sensor": s, e, ...)
        later = [n for n in names if n in DERIVED_FIELDS] if self.format_version >= 3 else []
        for name in names:
            if name in later:
                continue
            if name not in self._file:
                raise KeyError(f"{self.path}: no dataset {name!r}")
            try:
                value = self._file[name][index]
            except (OSError, ValueError) as exc:
                raise ShardError(f"{self.path}: frame {index}: cannot read {name!r} "
                                 f"(corrupt chunk?): {short_error(exc)}") from None
            if name in PROB_FIELDS and self.format_version >= 2:
                value = np.moveaxis(value, -1, 0)  # cell-major on disk: a (5, H, W) view
            if name == "labels" and value.max(initial=0) >= N_CLASSES:  # 255: ignored
                bad = value[(value >= N_CLASSES) & (value != IGNORE_INDEX)]
                if bad.size:  # (the loss said only "label outside [0, 5)", no file)
                    raise ShardError(f"{self.path}: frame {index}: label {int(bad[0])} is no "
                                     f"class (0..{N_CLASSES - 1}) nor ignored ({IGNORE_INDEX})")
            out[name] = value if stored else self.dequantise(name, value)
        for name in later:  # format 3: computed from a stored grid (read once)
            src = DERIVED_FIELDS[name]
            source = out[src] if src in out else self.get(index, [src])[src]
            out[name] = derive(name, source)
        return {n: out[n] for n in names}

    def dequantise(self, name: str, value: np.ndarray) -> np.ndarray:
        """A stored array of dataset ``name`` as read by :meth:`get` (probabilities:
        a new ``float32`` array in [0, 1]; other datasets: ``value`` itself)."""
        if name not in PROB_FIELDS:
            return value
        value = np.array(value, dtype=np.float32, order="C")  # a view of v2 data: C order
        if self.prob_scale != 1:
            value /= np.float32(self.prob_scale)
        return value

    def __getitem__(self, index: int) -> Frame:
        names = [*FRAME_FIELDS] + (["masses"] if self.has_masses else [])
        d = self.get(index, names)
        return Frame(
            pignistic=d["pignistic"], pignistic_prev=d["pignistic_prev"], labels=d["labels"],
            visible=d["visible"], sensor=d["sensor"], gis=d["gis"], ego_pose=d["ego_pose"],
            time=float(d["time"]), seed=int(d["seed"]), step=int(d["step"]),
            masses=d.get("masses"),
        )

    def class_counts(self) -> np.ndarray:
        """``(5,) int64`` cells of each class summed over the shard's frames."""
        try:
            return self._file["class_counts"][()].sum(axis=0).astype(np.int64)
        except OSError as exc:
            raise ShardError(f"{self.path}: cannot read class_counts: {short_error(exc)}") from None

    def verify(self, names: Sequence[str] | None = None) -> None:
        """Read every chunk (checksums included); raise :class:`ShardError` on the first bad one."""
        for name in names or [n for n in self._file]:
            for i in range(self.n_frames):
                self.get(i, [name])

    def close(self) -> None:
        """Close the file (idempotent)."""
        self._file.close()

    def __enter__(self) -> ShardReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
