"""Constants and helpers of the shard format (documented in :mod:`dstenv.data.shards`)."""

from __future__ import annotations

from dstenv.io import partial_path  # noqa: F401 - re-exported: the shard format's temp name

import json
from collections.abc import Mapping
from typing import Any

import numpy as np

from dstenv.dst.frame import CLASSES, NUM_CLASSES, NUM_SETS

__all__ = [
    "FORMAT", "FORMAT_VERSION", "READ_VERSIONS", "QUANT_SCALE", "QUANT_MAX_ERROR", "N_CLASSES",
    "N_MASSES", "FRAME_FIELDS", "ShardError", "class_names", "partial_path", "prob_shape",
    "grid_fields", "DERIVED_FIELDS",
]

FORMAT = "dstenv-shard"
#: written by this dstenv: 3 derives ``visible`` from ``sensor`` instead of storing it
FORMAT_VERSION = 3
#: read by this dstenv: 2 stored ``visible``; 1 also stored probabilities as planes
#: ``(N, 5, H, W)`` instead of cell-major ``(N, H, W, 5)`` (otherwise the same)
READ_VERSIONS = (1, 2, 3)
#: uint8 quantisation: ``q = rint(QUANT_SCALE * p)``.
QUANT_SCALE = 255
#: Largest absolute error of a dequantised probability.
QUANT_MAX_ERROR = 1.0 / (2 * QUANT_SCALE)
# frames are buffered and written in blocks (fewer HDF5 calls); chunks stay one per frame
BUFFER_FRAMES = 16
BUFFER_BYTES = 32 << 20
N_CLASSES = NUM_CLASSES  # 5
N_MASSES = NUM_SETS  # 32

# per-frame datasets by trailing shape: (H, W) grids, (5, H, W) probabilities, scalars;
# GRID_FIELDS are the grids a reader returns, grid_fields(version) those stored
GRID_FIELDS = {"labels": np.uint8, "visible": np.bool_, "sensor": np.uint8, "gis": np.uint8}
#: grids that format 3 computes from another one instead of storing:
#: ``visible = sensor != 0`` (:func:`dstenv.sensing.visible_mask`, its one definition)
DERIVED_FIELDS = {"visible": "sensor"}
PROB_FIELDS = ("pignistic", "pignistic_prev")
SCALAR_FIELDS = {"time": np.float64, "seed": np.int64, "step": np.int64}
#: the small per-frame records (64 frames per chunk, written once per shard)
RECORD_FIELDS: tuple[str, ...] = ("ego_pose", *SCALAR_FIELDS, "class_counts")
#: Every dataset a valid shard holds (``masses`` is optional).
FRAME_FIELDS: tuple[str, ...] = (
    *PROB_FIELDS, *GRID_FIELDS, "ego_pose", *SCALAR_FIELDS, "class_counts",
)


def prob_shape(version: int, h: int, w: int) -> tuple[int, int, int]:
    """Stored shape of one frame of ``pignistic`` / ``pignistic_prev`` in a shard of
    format ``version``: ``(H, W, 5)`` from version 2, ``(5, H, W)`` before."""
    return (h, w, N_CLASSES) if version >= 2 else (N_CLASSES, h, w)


def grid_fields(version: int) -> dict[str, Any]:
    """The ``(N, H, W)`` grid datasets a shard of format ``version`` stores, with dtypes
    (from version 3 without :data:`DERIVED_FIELDS`)."""
    if version < 3:
        return dict(GRID_FIELDS)
    return {k: v for k, v in GRID_FIELDS.items() if k not in DERIVED_FIELDS}


def derive(name: str, source: np.ndarray) -> np.ndarray:
    """A derived grid (:data:`DERIVED_FIELDS`) from its source grid, ``(..., H, W)``."""
    if name != "visible":
        raise KeyError(f"no derived field {name!r}")
    from dstenv.sensing.labels import visible_mask

    return visible_mask(source)


class ShardError(ValueError):
    """A shard file is missing, truncated, corrupt or inconsistent (message names the file)."""


def class_names() -> tuple[str, ...]:
    """Class names in channel order, from :data:`dstenv.dst.CLASSES` (the one definition)."""
    return tuple(str(c) for c in CLASSES)


def encode_attr(value: Any) -> tuple[Any, bool]:
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


def short_error(exc: BaseException) -> str:
    """First line of an exception message (HDF5 errors can be multi-line)."""
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__
