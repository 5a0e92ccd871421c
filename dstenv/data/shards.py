"""Shard files: HDF5 containers of labelled frames, readable with ``h5py`` alone.

Format (``format = "dstenv-shard"``, ``format_version = 1``)
------------------------------------------------------------
One shard holds ``N`` :class:`dstenv.frame.Frame` records of one grid shape
``(H, W)``. Every per-frame dataset has ``N`` as its first axis and is chunked one
frame per chunk (random access reads exactly one chunk per array), compressed
(``gzip`` level 6 by default, or ``lzf``) and checksummed (``fletcher32``: a
corrupted chunk raises on read instead of returning wrong numbers).

===================  ======================  =========================================
dataset              shape, dtype            meaning (axes: :mod:`dstenv.grid`)
===================  ======================  =========================================
``pignistic``        (N, 5, H, W) uint8 or   BetP at t over ``attrs["classes"]``
                     float32
``pignistic_prev``   (N, 5, H, W) as above   BetP at t-1 (the paper's FCN input is both)
``labels``           (N, H, W) uint8         class index, or 255 (``IGNORE_INDEX``)
``visible``          (N, H, W) bool          cell observed by this sweep
``sensor``           (N, H, W) uint8         0 unknown, 1 free, 2 occupied
``gis``              (N, H, W) uint8         0 none, 1 building, 2 road, 3 intermediate
``ego_pose``         (N, 3) float64          world ``(x [m], y [m], yaw [rad])``
``time``             (N,) float64            seconds since the episode's reset
``seed``             (N,) int64              episode (map) seed of the frame
``step``             (N,) int64              step index within the episode
``class_counts``     (N, 5) int64            cells of each class in ``labels``
``masses``           (N, 32, H, W) float32   optional raw DST masses (bit layout of
                                             :mod:`dstenv.dst`), never quantised
===================  ======================  =========================================

Measured at 256 x 256 (default city, stride 10; ``dstenv bench data``): uint8 +
gzip 6 stores about 24 KB per frame, against 919 KB uncompressed uint8 and 2.9 MB
as float32; gzip 4 gave 38 KB, gzip 9 22 KB at 4x the write time, lzf 67 KB.

Quantisation: when ``attrs["prob_dtype"] == "uint8"`` the probabilities are stored
as ``q = rint(255 * p)`` and read as ``p' = q / 255``, so ``|p' - p| <= 1/510``
(about 0.00196) per value; the five classes of a cell then sum to 1 only within
``5/510``. ``float32`` storage is exact.

Root attributes (the shard describes itself): ``format``, ``format_version``,
``dstenv_version``, ``classes`` (class names in channel order, from
:data:`dstenv.dst.CLASSES`), ``grid_shape`` ``[H, W]``, ``cell_size`` [m],
``prob_dtype``, ``prob_scale`` (255 or 1), ``has_masses``, ``n_frames``,
``complete`` (always true in a final file), ``seed`` (the shard's task seed),
``config`` (the full pipeline configuration as JSON), and whatever else the
producer passes (e.g. ``split``, ``task``, ``scenario``). Attribute values that are
dicts or lists of non-numbers are stored as JSON strings; their names are listed in
the attribute ``json_attrs``.

Reading with h5py alone::

    with h5py.File("shard-00000.h5") as f:
        p = f["pignistic"][7] / f.attrs["prob_scale"]     # (5, H, W)
        config = json.loads(f.attrs["config"])

Atomicity and determinism: :class:`ShardWriter` writes ``NAME.partial`` and renames
it to ``NAME`` only after a successful close (after ``fsync``), so a killed run never
leaves a file under the final name. No timestamps are stored (``track_times=False``),
so the same frames and attributes give a byte-identical file.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any

import h5py
import numpy as np

from dstenv import __version__
from dstenv.dst.frame import CLASSES, NUM_CLASSES, NUM_SETS
from dstenv.frame import IGNORE_INDEX, Frame

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "QUANT_SCALE",
    "QUANT_MAX_ERROR",
    "FRAME_FIELDS",
    "ShardError",
    "ShardWriter",
    "ShardReader",
    "partial_path",
    "class_names",
]

FORMAT = "dstenv-shard"
FORMAT_VERSION = 1
#: uint8 quantisation: ``q = rint(QUANT_SCALE * p)``.
QUANT_SCALE = 255
#: Largest absolute error of a dequantised probability.
QUANT_MAX_ERROR = 1.0 / (2 * QUANT_SCALE)
# frames are buffered and written in blocks (fewer HDF5 calls); chunks stay one per frame
_BUFFER_FRAMES = 16
_BUFFER_BYTES = 32 << 20
N_CLASSES = NUM_CLASSES  # 5
N_MASSES = NUM_SETS  # 32

# name -> (trailing shape kind, dtype); "grid" = (H, W), "probs" = (5, H, W)
_GRID_FIELDS = {"labels": np.uint8, "visible": np.bool_, "sensor": np.uint8, "gis": np.uint8}
_PROB_FIELDS = ("pignistic", "pignistic_prev")
_SCALAR_FIELDS = {"time": np.float64, "seed": np.int64, "step": np.int64}
#: Every dataset a valid shard holds (``masses`` is optional).
FRAME_FIELDS: tuple[str, ...] = (
    *_PROB_FIELDS, *_GRID_FIELDS, "ego_pose", *_SCALAR_FIELDS, "class_counts",
)


class ShardError(ValueError):
    """A shard file is missing, truncated, corrupt or inconsistent (message names the file)."""


def class_names() -> tuple[str, ...]:
    """Class names in channel order, from :data:`dstenv.dst.CLASSES` (the one definition)."""
    return tuple(str(c) for c in CLASSES)


def partial_path(path: str | Path) -> Path:
    """The temporary name a shard is written under before the final rename."""
    path = Path(path)
    return path.with_name(path.name + ".partial")


def _encode_attr(value: Any) -> tuple[Any, bool]:
    """Value to store as an HDF5 attribute, and whether it was JSON-encoded."""
    if isinstance(value, Mapping) or (
        isinstance(value, (list, tuple))
        and not all(isinstance(v, (int, float, np.integer, np.floating)) for v in value)
    ):
        return json.dumps(value, sort_keys=True, allow_nan=False), True
    if isinstance(value, (list, tuple)):
        return np.asarray(value), False
    if value is None:
        return json.dumps(None), True
    return value, False


class ShardWriter:
    """Write frames to one shard; a context manager that commits on a clean exit.

    Args:
        path: final file name (``.h5``); the data go to ``path + ".partial"`` first.
        attrs: root attributes. ``config`` (dict) and ``seed`` (int) are required;
            ``cell_size`` [m] is taken from ``attrs`` or ``config["grid"]["cell_size"]``.
        quantize: store probabilities as uint8 (error <= 1/510) instead of float32.
        masses: also store ``frame.masses`` (``(32, H, W) float32``, every frame must
            have them).
        compression: ``"gzip"``, ``"lzf"`` or ``None``.
        compression_opts: gzip level (0-9).

    Raises:
        ValueError: on missing attributes or a frame of the wrong shape or dtype.
    """

    def __init__(
        self,
        path: str | Path,
        attrs: Mapping[str, Any],
        *,
        quantize: bool = True,
        masses: bool = False,
        compression: str | None = "gzip",
        compression_opts: int | None = 6,
    ) -> None:
        self.path = Path(path)
        self.tmp_path = partial_path(self.path)
        missing = [k for k in ("config", "seed") if k not in attrs]
        if missing:
            raise ValueError(f"{self.path}: shard attrs lack {', '.join(missing)}")
        self.attrs = dict(attrs)
        if "cell_size" not in self.attrs:
            try:
                self.attrs["cell_size"] = float(self.attrs["config"]["grid"]["cell_size"])
            except (KeyError, TypeError):
                raise ValueError(
                    f"{self.path}: give attrs['cell_size'] or config['grid']['cell_size']"
                ) from None
        if compression not in ("gzip", "lzf", None):
            raise ValueError(f"compression must be 'gzip', 'lzf' or None, got {compression!r}")
        self.quantize = quantize
        self.masses = masses
        self._filters: dict[str, Any] = {"compression": compression, "fletcher32": True}
        if compression == "gzip":
            self._filters["compression_opts"] = compression_opts
        self._file: h5py.File | None = None
        self._shape: tuple[int, int] | None = None
        self._pending: list[dict[str, Any]] = []
        self._pending_bytes = 0
        self.n_frames = 0

    def __enter__(self) -> ShardWriter:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = h5py.File(self.tmp_path, "w", track_order=False)
        return self

    def _create(self, h: int, w: int) -> None:
        f = self._file
        assert f is not None
        prob_dtype = np.uint8 if self.quantize else np.float32
        specs: dict[str, tuple[tuple[int, ...], Any]] = {
            **{k: ((N_CLASSES, h, w), prob_dtype) for k in _PROB_FIELDS},
            **{k: ((h, w), dt) for k, dt in _GRID_FIELDS.items()},
            "ego_pose": ((3,), np.float64),
            **{k: ((), dt) for k, dt in _SCALAR_FIELDS.items()},
            "class_counts": ((N_CLASSES,), np.int64),
        }
        if self.masses:
            specs["masses"] = ((N_MASSES, h, w), np.float32)
        for name, (tail, dtype) in specs.items():
            f.create_dataset(
                name, shape=(0, *tail), maxshape=(None, *tail), chunks=(1, *tail),
                dtype=dtype, track_times=False, **self._filters,
            )
        self._shape = (h, w)

    def add(self, frame: Frame) -> None:
        """Append one frame (arrays as documented in :class:`dstenv.frame.Frame`)."""
        if self._file is None:
            raise RuntimeError("ShardWriter.add() outside a 'with' block")
        h, w = frame.labels.shape
        if self._shape is None:
            self._create(h, w)
        values = self._check(frame)
        self._pending.append(values)
        self._pending_bytes += sum(np.asarray(v).nbytes for v in values.values())
        self.n_frames += 1
        if len(self._pending) >= _BUFFER_FRAMES or self._pending_bytes >= _BUFFER_BYTES:
            self._flush(self._file)

    def _flush(self, f: h5py.File) -> None:
        """Write buffered frames: one resize and one write per dataset (still 1 chunk/frame)."""
        if not self._pending:
            return
        start, k = self.n_frames - len(self._pending), len(self._pending)
        for name in self._pending[0]:
            ds = f[name]
            ds.resize(start + k, axis=0)
            ds[start:start + k] = np.stack([np.asarray(v[name]) for v in self._pending])
        self._pending, self._pending_bytes = [], 0

    def _check(self, frame: Frame) -> dict[str, Any]:
        h, w = self._shape  # type: ignore[misc]
        out: dict[str, Any] = {}
        for name in _PROB_FIELDS:
            p = np.asarray(getattr(frame, name))
            _expect(self.path, name, p, (N_CLASSES, h, w))
            if not np.all(np.isfinite(p)):
                raise ValueError(f"{self.path}: frame {self.n_frames}: {name} has NaN/inf")
            out[name] = (
                np.rint(np.clip(p, 0.0, 1.0) * QUANT_SCALE).astype(np.uint8)
                if self.quantize else p.astype(np.float32)
            )
        for name, dtype in _GRID_FIELDS.items():
            a = np.asarray(getattr(frame, name))
            _expect(self.path, name, a, (h, w))
            out[name] = a.astype(dtype)
        labels = out["labels"]
        bad = (labels >= N_CLASSES) & (labels != IGNORE_INDEX)
        if bad.any():
            raise ValueError(f"{self.path}: labels hold value {int(labels[bad][0])}; allowed "
                             f"0..{N_CLASSES - 1} and {IGNORE_INDEX}")
        out["ego_pose"] = np.asarray(frame.ego_pose, dtype=np.float64)
        _expect(self.path, "ego_pose", out["ego_pose"], (3,))
        out["time"], out["seed"], out["step"] = float(frame.time), int(frame.seed), int(frame.step)
        out["class_counts"] = np.bincount(labels.ravel(), minlength=256)[:N_CLASSES]
        if self.masses:
            if frame.masses is None:
                raise ValueError(f"{self.path}: masses=True but frame {self.n_frames} has none")
            m = np.asarray(frame.masses)
            _expect(self.path, "masses", m, (N_MASSES, h, w))
            out["masses"] = m.astype(np.float32)
        return out

    def _write_attrs(self, f: h5py.File) -> None:
        assert self._shape is not None
        attrs: dict[str, Any] = dict(self.attrs)
        attrs.update(
            format=FORMAT,
            format_version=FORMAT_VERSION,
            dstenv_version=__version__,
            classes=list(class_names()),
            grid_shape=list(self._shape),
            prob_dtype="uint8" if self.quantize else "float32",
            prob_scale=QUANT_SCALE if self.quantize else 1,
            has_masses=bool(self.masses),
            n_frames=self.n_frames,
            complete=True,
        )
        json_keys = []
        for key in sorted(attrs):
            value, encoded = _encode_attr(attrs[key])
            f.attrs[key] = value
            if encoded:
                json_keys.append(key)
        f.attrs["json_attrs"] = json.dumps(json_keys)

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        f, self._file = self._file, None
        if f is None:
            return
        if exc_type is None and self.n_frames == 0:
            f.close()
            self.tmp_path.unlink(missing_ok=True)
            raise ValueError(f"{self.path}: no frames added; refusing to write an empty shard")
        try:
            if exc_type is None:
                self._flush(f)
                self._write_attrs(f)
                f.flush()
                fd = f.id.get_vfd_handle()
                os.fsync(fd)
        finally:
            f.close()
        if exc_type is not None:
            self.tmp_path.unlink(missing_ok=True)
            return
        try:
            os.replace(self.tmp_path, self.path)
        except OSError:
            self.tmp_path.unlink(missing_ok=True)
            raise
        _fsync_dir(self.path.parent)


def _fsync_dir(directory: Path) -> None:
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _expect(path: Path, name: str, a: np.ndarray, shape: tuple[int, ...]) -> None:
    if a.shape != shape:
        raise ValueError(f"{path}: frame field {name!r} has shape {a.shape}, expected {shape}")


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
            raise ShardError(f"{self.path}: not a readable HDF5 file (truncated or corrupt?): "
                             f"{_short(exc)}") from None
        try:
            self.attrs = self._read_attrs()
            self._validate()
        except ShardError:
            self._file.close()
            raise
        except (OSError, KeyError, ValueError, TypeError) as exc:
            self._file.close()
            raise ShardError(f"{self.path}: unreadable shard metadata: {_short(exc)}") from None

    def _read_attrs(self) -> dict[str, Any]:
        raw = dict(self._file.attrs)
        if raw.get("format") != FORMAT:
            raise ShardError(f"{self.path}: not a dstenv shard "
                             f"(attribute format={raw.get('format')!r})")
        if int(raw.get("format_version", -1)) != FORMAT_VERSION:
            raise ShardError(f"{self.path}: shard format_version {raw.get('format_version')} is "
                             f"not supported (this dstenv reads {FORMAT_VERSION})")
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
        expected = {
            **{k: (n, N_CLASSES, h, w) for k in _PROB_FIELDS},
            **{k: (n, h, w) for k in _GRID_FIELDS},
            "ego_pose": (n, 3), **{k: (n,) for k in _SCALAR_FIELDS},
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
        self.n_frames = n
        self.grid_shape: tuple[int, int] = (h, w)
        self.cell_size = float(a["cell_size"])
        self.classes: tuple[str, ...] = tuple(a["classes"])
        self.has_masses = bool(a.get("has_masses"))
        self._scale = float(a["prob_scale"])

    def __len__(self) -> int:
        return self.n_frames

    def get(self, index: int, names: Iterable[str]) -> dict[str, np.ndarray]:
        """Read selected arrays of frame ``index``.

        Args:
            index: frame index, ``-len <= index < len``.
            names: dataset names (see the module table); probabilities come back as
                ``float32`` in [0, 1] whatever the stored dtype.

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
        for name in names:
            if name not in self._file:
                raise KeyError(f"{self.path}: no dataset {name!r}")
            try:
                value = self._file[name][index]
            except (OSError, ValueError) as exc:
                raise ShardError(f"{self.path}: frame {index}: cannot read {name!r} "
                                 f"(corrupt chunk?): {_short(exc)}") from None
            if name in _PROB_FIELDS:
                value = value.astype(np.float32)
                if self._scale != 1:
                    value /= np.float32(self._scale)
            out[name] = value
        return out

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
            raise ShardError(f"{self.path}: cannot read class_counts: {_short(exc)}") from None

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


def _short(exc: BaseException) -> str:
    """First line of an exception message (HDF5 errors can be multi-line)."""
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__
