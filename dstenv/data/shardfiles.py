"""Which shard files make a :class:`~dstenv.data.datasets.ShardDataset`: a dataset
folder (the files its manifest lists, or, without one, the shards found in it), one
shard file, or a list of them; and the check that two shards belong to one dataset."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from dstenv.data.lock import LOCK_NAME, writer_of
from dstenv.data.manifest import MANIFEST_NAME, load_manifest, scan_shards
from dstenv.data.shards import ShardError

__all__ = ["resolve_files", "same_dataset"]


def resolve_files(root_or_files: str | Path | Sequence[str | Path], split: str | None
                  ) -> list[tuple[Path, int | None]]:
    """Shard files (and frame counts when a manifest knows them) of a dataset: those of
    ``split`` when a manifest says so (else every file: their own attribute decides).

    Raises:
        ValueError: a folder still being written, without manifest and shards, or a
            list that is empty, not a list, or names a file twice.
        FileNotFoundError: no such folder or file.
    """
    if isinstance(root_or_files, (str, Path)):
        root = Path(root_or_files)
        if root.is_file():
            return [(root, None)]
        busy = writer_of(root)
        if busy:  # a dataset being generated: its manifest and last shards are missing
            raise ValueError(f"{root}: still being written by {busy} ({root / LOCK_NAME}); "
                             "read it when that run is done")
        if (root / MANIFEST_NAME).is_file():
            m = load_manifest(root)
            return [(root / e["file"], int(e["frames"])) for e in m["shards"]
                    if split is None or e["split"] == split]
        if not root.is_dir():
            raise FileNotFoundError(f"{root}: no such dataset directory or shard file")
        found = scan_shards(root)
        if not found:  # (an empty dataset was silently 0 frames)
            raise ValueError(f"{root}: no {MANIFEST_NAME} and no shard files (*.h5); give a "
                             "dataset folder made by dstenv generate or kitti convert")
        return [(p, None) for p in found]
    if not isinstance(root_or_files, Sequence) or not root_or_files:
        raise ValueError(f"ShardDataset: a dataset folder, a shard file or a non-empty list "
                         f"of shard files, got {root_or_files!r}")
    files = [Path(p) for p in root_or_files]
    real = [os.path.realpath(p) for p in files]  # (another spelling of one file counted)
    if len(set(real)) != len(real):
        twice = next(p for p, r in zip(files, real) if real.count(r) > 1)
        raise ValueError(f"ShardDataset: {twice} is listed twice (its frames would count "
                         "twice)")
    return [(p, None) for p in files]


def same_dataset(first: tuple[Path, Any, Any], other: tuple[Path, Any, Any],
                 folder: bool) -> None:
    """Refuse shards of another geometry (they cannot be batched together) and, in a
    dataset folder, of another configuration (a folder mixing two datasets)."""
    (p0, g0, c0), (p1, g1, c1) = first, other
    if g1 != g0:
        raise ShardError(f"{p1}: grid {g1[0][0]} x {g1[0][1]} of {g1[1]:g} m, but {p0.name} "
                         f"has {g0[0][0]} x {g0[0][1]} of {g0[1]:g} m; keep one dataset per "
                         "folder (or pass the files of one)")
    if folder and c1 != c0:
        raise ShardError(f"{p1}: made with another configuration than {p0.name} (two datasets "
                         "in one folder); keep one dataset per folder")
