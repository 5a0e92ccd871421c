"""Writing shards: :class:`ShardWriter` (format in :mod:`dstenv.data.shards`)."""

from __future__ import annotations

import concurrent.futures as cf
import json
import math
import os
import re
from collections.abc import Mapping
from pathlib import Path
from types import TracebackType
from typing import Any

import h5py
import numpy as np

from dstenv import __version__
from dstenv.data.codec import (
    DEFLATE_ENGINES, DIRECT_COMPRESSIONS, class_counts, encode_chunk, observed_is,
    quantize_cells, quantize_check, same_bytes,
)
from dstenv.data import h5image
from dstenv.io import fsync_dir
from dstenv.data.format import (
    BUFFER_BYTES, BUFFER_FRAMES, FORMAT, FORMAT_VERSION, GRID_FIELDS, N_CLASSES, N_MASSES,
    PROB_FIELDS, QUANT_SCALE, RECORD_FIELDS, SCALAR_FIELDS, class_names, encode_attr,
    partial_path, prob_shape, short_error, grid_fields, DERIVED_FIELDS,
)
from dstenv.frame import IGNORE_INDEX, Frame

#: codes per grid: SensorState 0..2, MapClass 0..3 (labels: checked by class_counts)
CODE_LIMITS = {"sensor": 3, "gis": 4}

__all__ = ["ShardWriter"]


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
        compression_opts: gzip level (0-9; 1 by default: with the ISA-L engine the
            fastest level that keeps a 256x256 frame below 64 KB, see
            :mod:`dstenv.data.shards`).
        deflate: how gzip chunks are compressed: ``"isal"`` (default, ~5x faster)
            or ``"zlib"`` (the bytes h5py itself writes); both read back with h5py's
            built-in filter (:mod:`dstenv.data.codec`).
        threads: background threads that compress the grids while the caller
            produces the next frames (0, the default: compress in :meth:`add`; one
            worker process per core gains nothing from them). Only gzip and
            uncompressed shards are encoded here (:mod:`dstenv.data.codec`); lzf
            goes through h5py. With ``threads > 0`` chunks are deflated with zlib
            whatever ``deflate`` says: ISA-L from worker threads gave other bytes in 2
            of 20 runs, and a shard must be a pure function of its frames.

    With gzip or no compression every grid chunk is encoded once by
    :func:`dstenv.data.codec.encode_chunk` and written with ``write_direct_chunk``;
    a ``pignistic_prev`` equal (after quantisation) to the previous frame's
    ``pignistic``, as in every episode kept at stride 1, reuses that chunk's bytes.

    Raises:
        ValueError: on missing attributes or a frame of the wrong shape or dtype.

    Example (any producer, e.g. the KITTI converter)::

        with ShardWriter(out / "train" / "shard-00000.h5",
                         {"config": config, "seed": 0, "split": "train"}) as w:
            for frame in frames:
                w.add(frame)
        write_manifest(out)          # dstenv.data.manifest: scans and lists the shards
    """

    def __init__(
        self,
        path: str | Path,
        attrs: Mapping[str, Any],
        *,
        quantize: bool = True,
        masses: bool = False,
        compression: str | None = "gzip",
        compression_opts: int | None = 1,
        deflate: str = "isal",
        threads: int = 0,
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
        if deflate not in DEFLATE_ENGINES:
            raise ValueError(f"deflate must be one of {DEFLATE_ENGINES}, got {deflate!r}")
        self.quantize = quantize
        self.masses = masses
        self._filters: dict[str, Any] = {"compression": compression, "fletcher32": True}
        if compression == "gzip":
            self._filters["compression_opts"] = compression_opts
        self._direct = compression in DIRECT_COMPRESSIONS
        if not isinstance(threads, (int, np.integer)) or isinstance(threads, bool) or threads < 0:
            raise ValueError(f"threads must be an integer >= 0, got {threads!r}")  # -2 was 0
        self._threads = int(threads) if self._direct else 0
        # ISA-L only on the calling thread: its output from worker threads varied
        self._codec = (compression, compression_opts, "zlib" if self._threads else deflate)
        self._pool: cf.ThreadPoolExecutor | None = None
        self._last_prob: np.ndarray | None = None  # quantised pignistic of the last frame
        # quantised BetP is encoded in add() and dropped, but for _last_prob: three
        # buffers in turn spare the page faults of two fresh 327 KB arrays a frame
        self._qbufs: list[np.ndarray] = []
        self._last_chunk: Any = None  # its encoded chunk (bytes or Future)
        self._file: h5py.File | None = None
        self._fd: int | None = None  # the locked .partial file of an in-memory shard
        self._closed = False  # entered and left: a writer writes one shard once
        self._shape: tuple[int, int] | None = None
        self._datasets: dict[str, h5py.Dataset] = {}
        self._pending: list[dict[str, Any]] = []
        self._pending_bytes = 0
        self._capacity = 0  # frames the grid datasets hold room for (see _flush)
        self._records: dict[str, list[Any]] = {}  # small per-frame records until close
        self.n_frames = 0

    def __enter__(self) -> ShardWriter:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if self._file is not None or self._closed:
            raise RuntimeError(f"{self.path}: a ShardWriter is entered once; make a new one")
        try:  # in memory, written at close (h5image: a full disk crashed HDF5), but with
            if self.masses:  # masses (~100x larger) through HDF5's own file
                self._file = h5py.File(self.tmp_path, "w", track_order=False)
            else:
                self._file, self._fd = h5image.create(self.tmp_path)
        except OSError as exc:  # h5py's text named neither the file nor the cause
            busy = "lock" in str(exc) or "already open" in str(exc)
            raise OSError(exc.errno, f"{self.path}: cannot create {self.tmp_path.name}: " + (
                "another writer has it open (one writer per shard)" if busy
                else short_error(exc))) from None
        if self._threads:
            self._pool = cf.ThreadPoolExecutor(self._threads, thread_name_prefix="shard-codec")
        return self

    def _create(self, h: int, w: int) -> None:
        f = self._file
        assert f is not None
        prob_dtype = np.uint8 if self.quantize else np.float32
        specs: dict[str, tuple[tuple[int, ...], Any]] = {
            **{k: (prob_shape(FORMAT_VERSION, h, w), prob_dtype) for k in PROB_FIELDS},
            **{k: ((h, w), dt) for k, dt in grid_fields(FORMAT_VERSION).items()},
            "ego_pose": ((3,), np.float64),
            **{k: ((), dt) for k, dt in SCALAR_FIELDS.items()},
            "class_counts": ((N_CLASSES,), np.int64),
        }
        if self.masses:
            specs["masses"] = ((N_MASSES, h, w), np.float32)
        for name, (tail, dtype) in specs.items():
            # grids: one frame per chunk (random access); small per-frame records: 64 per
            # chunk, since a chunk per scalar would cost more index than data
            rows = 1 if len(tail) >= 2 else 64
            self._datasets[name] = f.create_dataset(
                name, shape=(0, *tail), maxshape=(None, *tail), chunks=(rows, *tail),
                dtype=dtype, track_times=False, **self._filters,
            )
        self._shape = (h, w)

    def add(self, frame: Frame) -> None:
        """Append one frame (arrays as documented in :class:`dstenv.frame.Frame`)."""
        if self._file is None:
            raise RuntimeError("ShardWriter.add() outside a 'with' block")
        if frame.labels is None or frame.visible is None:
            raise ValueError(f"{self.path}: frame {self.n_frames} has no labels; shards need "
                             "them (set the pipeline config frame.labels = true)")
        h, w = frame.labels.shape
        if self._shape is None:
            self._create(h, w)
        values = self._check(frame)
        self._pending_bytes += sum(np.asarray(v).nbytes for v in values.values())
        if self._direct:
            self._encode(values)
        self._pending.append(values)
        self.n_frames += 1
        if len(self._pending) >= BUFFER_FRAMES or self._pending_bytes >= BUFFER_BYTES:
            try:
                self._flush(self._file)
            except (OSError, RuntimeError) as exc:
                raise self._write_error(exc) from None

    def _encode(self, values: dict[str, Any]) -> None:
        """Replace the per-frame grids in ``values`` by their encoded chunks (or futures)."""
        prob = values["pignistic"]
        for name, value in values.items():
            if np.ndim(value) < 2:
                continue
            if (name == "pignistic_prev" and self._last_prob is not None
                    and same_bytes(value, self._last_prob)):
                values[name] = self._last_chunk  # stride 1: same bytes as the last chunk
            elif self._pool is not None:
                values[name] = self._pool.submit(encode_chunk, value, *self._codec)
            else:
                values[name] = encode_chunk(value, *self._codec)
        self._last_prob, self._last_chunk = prob, values["pignistic"]

    def _write_error(self, exc: BaseException) -> OSError:
        """A one-line OSError for an HDF5 write failure (HDF5 reports errno in its text)."""
        match = re.search(r"errno = (\d+)", str(exc))
        code = int(match.group(1)) if match else getattr(exc, "errno", None)
        reason = os.strerror(code) if code else short_error(exc)
        err = OSError(f"{self.path}: cannot write shard: {reason}")
        err.errno = code
        return err

    def _flush(self, f: h5py.File) -> None:
        """Write buffered frames' grids (one chunk per frame); keep their small records.

        Grid datasets grow by doubling (at least :data:`BUFFER_FRAMES` frames), not
        per flush, and are cut to ``n_frames`` at close (chunks never written take no
        space); the small records are written once per shard, at close.
        """
        if not self._pending:
            return
        start, k = self.n_frames - len(self._pending), len(self._pending)
        if start + k > self._capacity:
            self._capacity = max(2 * self._capacity, start + k, BUFFER_FRAMES)
            for name in self._pending[0]:
                if name not in RECORD_FIELDS:
                    self._datasets[name].resize(self._capacity, axis=0)
        for name in self._pending[0]:
            values = [v[name] for v in self._pending]
            if name in RECORD_FIELDS:
                self._records.setdefault(name, []).extend(values)
                continue
            ds = self._datasets[name]
            if isinstance(values[0], (bytes, cf.Future)):
                tail = (0,) * (ds.ndim - 1)
                for i, chunk in enumerate(values):
                    ds.id.write_direct_chunk((start + i, *tail),
                                             chunk if isinstance(chunk, bytes) else chunk.result())
            else:
                ds[start:start + k] = np.stack(values)
        self._pending, self._pending_bytes = [], 0

    def _finish(self) -> None:
        """Cut the grids to ``n_frames`` and write the small records (at close)."""
        n = self.n_frames
        for name, ds in self._datasets.items():
            ds.resize(n, axis=0)
            if name in RECORD_FIELDS:
                ds[:] = np.asarray(self._records[name], dtype=ds.dtype).reshape(ds.shape)

    def _check(self, frame: Frame) -> dict[str, Any]:
        h, w = self._shape  # type: ignore[misc]
        out: dict[str, Any] = {}
        reuse = self.quantize and self._direct and not self._threads
        if reuse and not self._qbufs:
            self._qbufs = [np.empty((h, w, N_CLASSES), np.uint8) for _ in range(3)]
        free = [b for b in self._qbufs if b is not self._last_prob]
        for name in PROB_FIELDS:
            p = np.asarray(getattr(frame, name))
            _expect(self.path, name, p, (N_CLASSES, h, w))
            try:
                # one pass: clip, scale, round, the NaN/inf check and the cell-major order
                out[name] = (quantize_cells(p, QUANT_SCALE, free.pop() if reuse else None)
                             if self.quantize else quantize_check(p))
            except ValueError:
                raise ValueError(f"{self.path}: frame {self.n_frames}: {name} has NaN/inf"
                                 ) from None
        for name, dtype in GRID_FIELDS.items():
            a = np.asarray(getattr(frame, name))
            _expect(self.path, name, a, (h, w))
            if name in DERIVED_FIELDS:  # not stored: it must be what readers derive
                if not observed_is(a, np.asarray(getattr(frame, DERIVED_FIELDS[name]))):
                    raise ValueError(
                        f"{self.path}: frame {self.n_frames}: {name} is not "
                        f"{DERIVED_FIELDS[name]} != 0 (unknown); shards of format "
                        f"{FORMAT_VERSION} derive it from {DERIVED_FIELDS[name]}: build it "
                        f"with dstenv.sensing.visible_mask(sensor)")
                continue
            if a.dtype != dtype and (a.dtype.kind not in "biu" or a.size and (
                    a.min() < 0 or a.max() > 255)):  # the cast wrapped 259 to 3, cut 1.7 to 1
                raise ValueError(f"{self.path}: frame {self.n_frames}: {name} must hold "
                                 f"integer codes 0..255, got {a.dtype} values "
                                 f"{a.min()!r}..{a.max()!r}")
            if name in CODE_LIMITS and a.size and int(a.max()) >= CODE_LIMITS[name]:
                raise ValueError(f"{self.path}: frame {self.n_frames}: {name} holds code "
                                 f"{int(a.max())}; allowed codes are 0..{CODE_LIMITS[name] - 1}")
            # encoded in add() on this thread: no copy; h5py's path and the codec
            # threads read them later, so they get a copy
            out[name] = a.astype(dtype, copy=not self._direct or self._threads > 0)
        try:
            out["class_counts"] = class_counts(out["labels"], N_CLASSES, IGNORE_INDEX)
        except ValueError as exc:
            raise ValueError(f"{self.path}: {exc}") from None
        out["ego_pose"] = np.array(frame.ego_pose, dtype=np.float64)
        _expect(self.path, "ego_pose", out["ego_pose"], (3,))
        out["time"], out["seed"], out["step"] = float(frame.time), int(frame.seed), int(frame.step)
        if not (np.isfinite(out["ego_pose"]).all() and math.isfinite(out["time"])
                and 0 <= out["seed"] < 2**63 and 0 <= out["step"] < 2**63):
            raise ValueError(f"{self.path}: frame {self.n_frames}: ego_pose and time must be "
                             "finite, seed and step integers in [0, 2**63), got "
                             f"{out['ego_pose'].tolist()}, {out['time']}, {out['seed']}, "
                             f"{out['step']}")
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
            value, encoded = encode_attr(attrs[key])
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
        self._closed = True
        try:
            self._close(f, exc_type)
        finally:
            if self._pool is not None:
                self._pool.shutdown(wait=True, cancel_futures=True)
                self._pool = None
            self._last_prob = self._last_chunk = None
            self._records, self._qbufs = {}, []

    def _close(self, f: h5py.File, exc_type: type[BaseException] | None) -> None:
        if exc_type is not None:
            self._discard(f)
            return
        if self.n_frames == 0:
            self._discard(f)
            raise ValueError(f"{self.path}: no frames added; refusing to write an empty shard")
        try:
            self._flush(f)
            self._finish()
            self._write_attrs(f)
            if self._fd is not None:
                fd, self._fd = self._fd, None
                h5image.commit(f, fd, self.tmp_path, self.path)
            else:
                f.flush()
                os.fsync(f.id.get_vfd_handle())
                f.close()
                os.replace(self.tmp_path, self.path)
        except (OSError, RuntimeError) as exc:
            self._discard(f)
            raise self._write_error(exc) from None
        except BaseException:
            self._discard(f)
            raise
        fsync_dir(self.path.parent)

    def _discard(self, f: h5py.File) -> None:
        """Close (ignoring HDF5 errors after a failed write) and delete the partial file."""
        fd, self._fd = self._fd, None
        h5image.discard(f, fd, self.tmp_path)


def _expect(path: Path, name: str, a: np.ndarray, shape: tuple[int, ...]) -> None:
    if a.shape != shape:
        raise ValueError(f"{path}: frame field {name!r} has shape {a.shape}, expected {shape}")
