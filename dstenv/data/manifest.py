"""``manifest.json``: the table of contents of a shard directory.

Layout of a dataset directory (written by ``dstenv generate`` or the KITTI
converter)::

    DIR/manifest.json
    DIR/train/shard-00000.h5 ...   DIR/val/...   DIR/test/...

The manifest (JSON, written atomically) holds ``format = "dstenv-manifest"``,
``format_version``, ``dstenv_version``, ``classes``, ``grid_shape``, ``cell_size``,
``meta`` (the producer's settings, e.g. the generate command), ``shards`` (one
entry per file: ``file`` relative to DIR, ``split``, ``frames``, ``bytes``,
``sha256``, ``class_counts``), ``splits`` (per split: ``shards``, ``frames``,
``class_counts``), ``frames``, ``class_counts`` and ``class_frequencies`` (share of
labelled cells per class). :func:`load_manifest` checks it against the files and
raises a one-line :class:`ManifestError` on any mismatch.
"""

from __future__ import annotations

import hashlib
import json
import posixpath
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from dstenv import __version__
from dstenv.data.sampling import SPLITS
from dstenv.data.shards import ShardReader, class_names
from dstenv.io import MANIFEST_FORMAT, atomic_write_text, file_sha256

__all__ = [
    "MANIFEST_NAME",
    "ManifestError",
    "scan_shards",
    "one_dataset",
    "shard_entry",
    "build_manifest",
    "write_manifest",
    "load_manifest",
]

MANIFEST_NAME = "manifest.json"
MANIFEST_VERSION = 1
#: split name of shards that carry no ``split`` attribute
UNSPLIT = "unsplit"


class ManifestError(ValueError):
    """A manifest is unreadable or does not match the shard files it lists."""


def scan_shards(root: str | Path) -> list[Path]:
    """Final shard files (``*.h5``) under ``root``, sorted; ``.partial`` files excluded."""
    return sorted(p for p in Path(root).rglob("*.h5") if p.is_file())


def one_dataset(root: str | Path) -> None:
    """ValueError if ``root``, a folder without a manifest, holds finished datasets (folders
    with a manifest) below it: their shards are not one dataset to read together; or is
    the split folder of a finished dataset."""
    root = Path(root)
    if root.name in (*SPLITS, UNSPLIT) and (root.parent / MANIFEST_NAME).is_file():
        raise ValueError(f"{root} is the {root.name} split of the dataset {root.parent}: give "
                         f"{root.parent} (and the split)")
    found = sorted(p.parent.relative_to(root).as_posix()
                   for p in root.rglob(MANIFEST_NAME) if p.is_file())
    if found:
        shown = ", ".join(found[:3]) + (f" and {len(found) - 3} more" if len(found) > 3 else "")
        raise ValueError(f"{root}: no {MANIFEST_NAME} of its own; it holds {len(found)} "
                         f"dataset(s) ({shown}): give one of them")


def attrs_sha256(attrs: Mapping[str, Any]) -> str:
    """SHA-256 of a shard's attributes (task, seeds, config...) as canonical JSON.

    Stored in the manifest and compared when a dataset is opened: a same-size shard of
    another seed or configuration differs here, at the cost of reading the attributes
    only (the whole-file ``sha256`` is the slower, complete check).
    """
    text = json.dumps(attrs, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def shard_entry(root: str | Path, path: str | Path, sha256: str | None = None) -> dict[str, Any]:
    """The manifest entry of one shard (opens and validates it).

    Raises:
        ShardError: the shard is unreadable.
    """
    path = Path(path)
    with ShardReader(path) as r:
        counts = r.class_counts()
        entry = {
            "file": path.relative_to(root).as_posix(),
            "split": str(r.attrs.get("split", UNSPLIT)),
            "frames": len(r),
            "bytes": path.stat().st_size,
            "sha256": sha256 or file_sha256(path),
            "attrs_sha256": attrs_sha256(r.attrs),
            "class_counts": [int(c) for c in counts],
            "grid_shape": list(r.grid_shape),
            "cell_size": r.cell_size,
        }
    return entry


def build_manifest(entries: Iterable[Mapping[str, Any]], meta: Mapping[str, Any] | None = None
                   ) -> dict[str, Any]:
    """Assemble a manifest from shard entries (see :func:`shard_entry`).

    Raises:
        ManifestError: no shards, or shards of different grid shapes / cell sizes.
    """
    shards = sorted((dict(e) for e in entries), key=lambda e: e["file"])
    if not shards:
        raise ManifestError("no shards to list in a manifest")
    shapes = {(tuple(e["grid_shape"]), float(e["cell_size"])) for e in shards}
    if len(shapes) > 1:
        raise ManifestError(f"shards mix grid shapes/cell sizes {sorted(shapes)}; "
                            "keep one geometry per dataset directory")
    (shape, cell_size), = shapes
    names = class_names()
    splits: dict[str, dict[str, Any]] = {}
    total = np.zeros(len(names), dtype=np.int64)
    for e in shards:
        s = splits.setdefault(e["split"], {"shards": 0, "frames": 0,
                                           "class_counts": [0] * len(names)})
        s["shards"] += 1
        s["frames"] += int(e["frames"])
        s["class_counts"] = [a + int(b) for a, b in zip(s["class_counts"], e["class_counts"])]
        total += np.asarray(e["class_counts"], dtype=np.int64)
    labelled = max(int(total.sum()), 1)
    return {
        "format": MANIFEST_FORMAT,
        "format_version": MANIFEST_VERSION,
        "dstenv_version": __version__,
        "classes": list(names),
        "grid_shape": list(shape),
        "cell_size": cell_size,
        "meta": dict(meta or {}),
        "frames": sum(int(e["frames"]) for e in shards),
        "class_counts": [int(c) for c in total],
        "class_frequencies": {n: float(c) / labelled for n, c in zip(names, total)},
        "splits": dict(sorted(splits.items())),
        "shards": shards,
    }


def write_manifest(root: str | Path, entries: Iterable[Mapping[str, Any]] | None = None,
                   meta: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Write ``root/manifest.json`` atomically and return it.

    Args:
        root: the dataset directory.
        entries: shard entries; ``None`` scans ``root`` and opens every shard.
        meta: producer settings to record (JSON-serialisable).
    """
    root = Path(root)
    if entries is None:
        entries = [shard_entry(root, p) for p in scan_shards(root)]
    manifest = build_manifest(entries, meta)
    atomic_write_text(root / MANIFEST_NAME, json.dumps(manifest, indent=1, sort_keys=True) + "\n")
    return manifest


def data_identity(root: str | Path) -> str:
    """SHA-256 over what a dataset holds: its shards' names and (per the manifest, else
    their sizes) contents, not where it lives. Two copies of one dataset agree; data
    made with other settings, seeds or frames do not."""
    root = Path(root)
    h = hashlib.sha256()
    try:
        entries = load_manifest(root, verify="none").get("shards", [])
        for e in sorted(entries, key=lambda e: str(e.get("file"))):
            h.update(f"{e.get('file')}:{e.get('sha256')}\n".encode())
    except ManifestError:  # shards without a manifest: their names and sizes
        for f in scan_shards(root):
            h.update(f"{f.relative_to(root)}:{f.stat().st_size}\n".encode())
    return h.hexdigest()


#: manifest shard entry key -> type (``attrs_sha256``: optional)
_ENTRY: dict[str, type | tuple[type, ...]] = {
    "file": str, "split": str, "frames": int, "bytes": int, "sha256": str,
    "class_counts": list, "grid_shape": list, "cell_size": (int, float)}


_KIND = {int: "an integer", str: "a string", list: "a list"}


def _check_entries(manifest: dict[str, Any], path: Path) -> None:
    """Every shard entry whole and typed, no file twice, and the totals (frames, splits,
    class counts, geometry) those of the entries: a hand-edited or damaged manifest is
    one line naming what is wrong, never a traceback or a wrong count."""
    fix = ("the manifest was edited or damaged; delete it and rerun the command that made "
           "the dataset (finished shards are kept and listed again)")
    shards = manifest.get("shards")
    if not isinstance(shards, list) or not shards:
        raise ManifestError(f"{path}: 'shards' must be a non-empty list of entries ({fix})")
    seen: set[str] = set()
    n_classes = len(class_names())
    for i, e in enumerate(shards):
        if not isinstance(e, dict):
            raise ManifestError(f"{path}: shard entry {i} is not an object ({fix})")
        for key, kind in _ENTRY.items():
            v = e.get(key)
            if not isinstance(v, kind) or isinstance(v, bool):
                raise ManifestError(f"{path}: shard entry {i} ({e.get('file', '?')}): {key!r} "
                                    f"is missing or not {_KIND.get(kind, 'a number')} "
                                    f"({fix})")
        ok = (e["frames"] >= 0 and e["bytes"] >= 0 and e["cell_size"] > 0
              and len(e["grid_shape"]) == 2 and len(e["class_counts"]) == n_classes
              and all(isinstance(x, int) and not isinstance(x, bool) and x > 0
                      for x in e["grid_shape"])
              and all(isinstance(x, int) and not isinstance(x, bool) and x >= 0
                      for x in e["class_counts"]))
        if not ok:
            raise ManifestError(f"{path}: shard entry {i} ({e['file']}): a negative count, a "
                                f"grid shape that is not two sizes or {n_classes} class counts "
                                f"expected ({fix})")
        name = posixpath.normpath(e["file"])  # ("train/./a.h5" and "val/../train/a.h5")
        if name in seen:
            raise ManifestError(f"{path}: {e['file']} is listed twice ({fix})")
        seen.add(name)
    try:
        derived = build_manifest(shards)
    except ManifestError as exc:
        raise ManifestError(f"{path}: {exc} ({fix})") from None
    from dstenv.config import leaf_diffs

    for key in ("frames", "grid_shape", "cell_size", "classes", "class_counts",
                "class_frequencies", "splits"):
        if manifest.get(key) != derived[key]:
            at, mine, theirs = (leaf_diffs(manifest.get(key), derived[key], key)
                                or [(key, manifest.get(key), derived[key])])[0]
            say = "say" if key in ("cell_size", "classes", "grid_shape") else "add up to"
            raise ManifestError(f"{path}: {at!r} is {mine!r:.60} but its shard entries {say} "
                                f"{theirs!r:.60} ({fix})")


class _DuplicateKey(Exception):
    """A JSON object that names one key twice (the last would win in silence)."""


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    keys = [k for k, _ in pairs]
    for k in keys:
        if keys.count(k) > 1:
            raise _DuplicateKey(repr(k))
    return dict(pairs)


def load_manifest(root: str | Path, verify: str = "attrs") -> dict[str, Any]:
    """Read ``root/manifest.json`` and check it against the shard files.

    Args:
        root: the dataset directory.
        verify: ``"none"`` (parse only), ``"size"`` (every listed file exists inside
            ``root`` with the listed byte size, no unlisted shard), ``"attrs"`` (the
            default: also open each shard and compare its frame count, its class counts
            and the hash of its attributes, which names its seeds, task and
            configuration; cheap),
            ``"frames"`` (also read every chunk: its checksum) or ``"hash"`` (instead,
            the SHA-256 of every byte).

    Raises:
        ManifestError: one line naming the manifest and the first mismatch.
    """
    root = Path(root)
    path = root / MANIFEST_NAME
    levels = ("none", "size", "attrs", "frames", "hash")
    if verify not in levels:
        raise ValueError(f"verify must be one of {', '.join(levels)}, got {verify!r}")
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"), object_pairs_hook=_unique_keys)
    except FileNotFoundError:
        raise ManifestError(f"{path}: no manifest (not a dataset directory?)") from None
    except _DuplicateKey as exc:
        raise ManifestError(f"{path}: key {exc} appears twice in one object; the manifest was "
                            "edited: delete it and rerun the command that made the dataset"
                            ) from None
    except (OSError, ValueError) as exc:  # bad JSON or UTF-8, an integer of 5000 digits
        raise ManifestError(f"{path}: unreadable manifest: {' '.join(str(exc).split())}"
                            ) from None
    if not isinstance(manifest, dict) or manifest.get("format") != MANIFEST_FORMAT:
        raise ManifestError(f"{path}: not a dstenv manifest")
    if manifest.get("format_version") != MANIFEST_VERSION:
        raise ManifestError(f"{path}: manifest format_version {manifest.get('format_version')} "
                            f"not supported (this dstenv reads {MANIFEST_VERSION})")
    if verify == "none":
        return manifest
    _check_entries(manifest, path)
    hint = ("the files changed after the manifest was written; regenerate them (a new --out, "
            "or delete the changed shards and rerun the command that made them)")
    listed = set()
    inside = root.resolve()
    for e in manifest.get("shards", []):
        if not isinstance(e, dict) or not isinstance(e.get("file"), str):
            raise ManifestError(f"{path}: malformed shard entry {e!r}")
        f = root / e["file"]
        if inside not in f.resolve().parents:
            raise ManifestError(f"{path}: shard entry {e['file']!r} points outside {root}; "
                                "a manifest lists only files inside its dataset folder")
        listed.add(f.resolve())
        if not f.is_file():
            raise ManifestError(f"{path}: lists {e['file']} but that file is missing ({hint})")
        size = f.stat().st_size
        if size != e["bytes"]:
            raise ManifestError(f"{path}: {e['file']} is {size} bytes on disk, the manifest says "
                                f"{e['bytes']} ({hint})")
        if verify in ("attrs", "frames", "hash"):
            with ShardReader(f) as r:
                if len(r) != e["frames"]:
                    raise ManifestError(f"{path}: {e['file']} holds {len(r)} frames, the "
                                        f"manifest says {e['frames']} ({hint})")
                if "attrs_sha256" in e and attrs_sha256(r.attrs) != e["attrs_sha256"]:
                    raise ManifestError(f"{path}: {e['file']} was made with other settings or "
                                        f"seeds than the manifest lists ({hint})")
                if r.attrs.get("split", e["split"]) != e["split"]:  # (an edited split)
                    raise ManifestError(f"{path}: {e['file']} is a shard of split "
                                        f"{r.attrs.get('split')!r}, the manifest says "
                                        f"{e['split']!r} (the manifest was edited; delete "
                                        "it and rerun the command that made the dataset)")
                counts = [int(c) for c in r.class_counts()]
                if counts != e["class_counts"]:
                    raise ManifestError(f"{path}: {e['file']} holds class counts {counts}, the "
                                        f"manifest says {e['class_counts']} ({hint})")
                if verify == "frames":  # every chunk read: a corrupt one raises ShardError
                    r.verify()
        if verify == "hash" and file_sha256(f) != e["sha256"]:
            raise ManifestError(f"{path}: {e['file']} content differs from its SHA-256 ({hint})")
    for f in scan_shards(root):
        if f.resolve() not in listed:
            inner = next((d for d in f.parents if d != root and (d / MANIFEST_NAME).is_file()
                          and root in d.parents), None)
            if inner is not None:  # a finished dataset inside this one: not a changed file
                raise ManifestError(f"{root} holds another dataset, {inner.relative_to(root)} "
                                    f"(its own {MANIFEST_NAME}): move it out of {root}")
            raise ManifestError(f"{path}: shard {f.relative_to(root).as_posix()} is not listed "
                                f"({hint})")
    return manifest
