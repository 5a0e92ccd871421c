"""Resuming ``dstenv generate``: which finished shards of an output folder a rerun keeps.

A shard is kept when it was made by the same task (settings, split, index, frames) with
the same configuration and reads back whole (every chunk's checksum, and the SHA-256
the last manifest listed); a longer run regenerates a short last shard. Anything else
in the folder (shards of other settings or of another run, someone else's
``manifest.json``) is refused with one line that names the setting as the command line
spells it (``--float32: off, now on``), never mixed in.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from dstenv.config import leaf_diffs
from dstenv.data.generate import GenerateError, ShardTask, pipeline_config
from dstenv.data.manifest import (MANIFEST_NAME, ManifestError, load_manifest, scan_shards,
                                  shard_entry)
from dstenv.data.shards import ShardError, ShardReader
from dstenv.io import file_sha256

__all__ = ["prepare", "FLAGS"]

#: task keys -> the ``dstenv generate`` flag that sets them
FLAGS: dict[str, str] = {
    "seed": "--seed", "scenario": "--scenario", "split": "--split", "frames": "--frames",
    "frames_per_shard": "--frames-per-shard", "episode_length": "--episode-length",
    "stride": "--stride", "warmup": "--warmup", "episodes_per_map": "--episodes-per-map",
    "masses": "--masses", "quantize": "--float32", "compression": "--compression",
    "compression_level": "--gzip-level", "deflate": "--deflate",
}
#: configuration leaves that a generate flag sets (the rest: --scenario or --set)
CONFIG_FLAGS: dict[str, str] = {"frame.masses": "masses", "grid.height": "--grid (height)",
                                "grid.width": "--grid (width)", "grid.cell_size": "--cell-size"}


def _existing(out: Path, task: ShardTask, listed: str = "") -> dict[str, Any] | None:
    """Manifest entry of a finished shard for ``task``, or None if it must be (re)made.

    A kept shard is read in full first (every chunk's checksum) and, when the last
    manifest listed it (``listed``: its SHA-256), its bytes must still hash to that: a
    shard with a corrupt chunk, or changed since, is set aside as ``NAME.corrupt`` and
    made again, never listed in the manifest with the hash of its corrupt bytes.
    """
    path = out / task.file
    if not path.exists():
        return None
    config, new_task = pipeline_config(task.spec), task.describe()
    try:
        with ShardReader(path) as r:
            old_task, old_config = r.attrs.get("task"), r.attrs.get("config")
            same = old_config == config and old_task == new_task
            if same:
                r.verify()
        sha = file_sha256(path) if same and listed else ""
        if sha and sha != listed:
            raise ShardError(f"{path}: its bytes changed since the manifest listed them")
    except ShardError as exc:
        keep = path.with_name(path.name + ".corrupt")
        path.replace(keep)
        print(f"dstenv generate: {exc}; kept as {keep.name}, regenerating", file=sys.stderr)
        return None
    if old_config != config:
        diff = leaf_diffs(old_config, config)  # (pipeline_config is plain JSON data already)
        said = "; ".join(_change(CONFIG_FLAGS.get(k, k), a, b) for k, a, b in diff[:3]) or "?"
        how = "" if all(k in CONFIG_FLAGS for k, _, _ in diff) else ": another --scenario or --set"
        raise GenerateError(f"{path} was made with another configuration ({said}){how}; use "
                            "another --out or remove the old shards")
    if old_task != new_task:
        diff = sorted(k for k in set(new_task) | set(old_task or {})
                      if (old_task or {}).get(k) != new_task.get(k))
        if diff == ["frames"] and new_task["frames"] > (old_task or {}).get("frames", 0):
            return None  # same episode stream, longer: regenerate this shard (a superset)
        if diff == ["frames"]:  # shorter: that would drop frames already made
            raise GenerateError(f"{path} holds {old_task['frames']} frames, this run makes "
                                f"{new_task['frames']} there: it would drop frames; give "
                                "--frames at least the dataset's, or use another --out")
        k = next((d for d in diff if d != "frames"), diff[0])  # the cause, not its effect
        said = _change(k, (old_task or {}).get(k), new_task.get(k))
        raise GenerateError(f"{path} was made with other settings ({said}); use another "
                            "--out or remove the old shards")
    return shard_entry(out, path, sha or None)


def _change(key: str, was: Any, now: Any) -> str:
    """``"FLAG: was, now now"``: a setting as the generate command line spells it."""
    def shown(v: Any) -> str:
        if key == "quantize":  # --float32 stores what quantize=False does
            return "off" if v else "on"
        if key == "compression" and v is None:
            return "none"
        if isinstance(v, bool):
            return "on" if v else "off"
        return v if isinstance(v, str) else repr(v)
    return f"{FLAGS.get(key, key)}: {shown(was)}, now {shown(now)}"


def _made_with(path: Path, tasks: list[ShardTask]) -> str:
    """``"; made with FLAG: old, now new"`` (or what else set a stray shard apart), or ``""``."""
    try:
        with ShardReader(path) as r:
            old = r.attrs.get("task") or {}
    except ShardError:
        return ""
    runs = [t.describe() for t in tasks]
    diff = [d for d in leaf_diffs(old, runs[0] if runs else {})
            if d[0] not in ("split", "index", "frames")]
    if diff:
        return f"; made with {_change(*diff[0])}"
    splits = sorted({str(r.get("split")) for r in runs})
    if str(old.get("split")) not in splits and not (tasks and tasks[0].spec.split == "auto"):
        return f"; a {old['split']} shard, this run writes {', '.join(splits)} only (--split)"
    if old:  # the same settings: a run of more frames made it
        return (f"; a run of more --frames made it: this one makes "
                f"{sum(t.frames for t in tasks)}, give at least the dataset's")
    return ""


def prepare(out: Path, tasks: list[ShardTask]) -> tuple[dict[str, dict[str, Any]], list[ShardTask]]:
    """The shards of ``tasks`` already finished in ``out`` (their manifest entries) and the
    tasks still to run; GenerateError for a folder this run must not write into (not
    writable, someone else's manifest, shards of other settings)."""
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / ".dstenv-write-test.partial"
        probe.write_bytes(b"ok")
        probe.unlink()
    except OSError as exc:
        raise GenerateError(f"output directory {out} is not writable: "
                            f"{exc.strerror or exc}") from None
    known: dict[str, str] = {}  # file -> sha256 the last manifest listed
    if (out / MANIFEST_NAME).exists():  # the run rewrites it: never someone else's file
        try:
            listed = load_manifest(out, verify="none")
        except ManifestError:
            raise GenerateError(f"{out / MANIFEST_NAME}: not a dstenv manifest, and this run "
                                "would replace it; use another --out") from None
        maker = listed.get("meta", {}).get("command")
        if maker is not None and maker != "generate":  # its shards' settings are not ours
            raise GenerateError(f"{out} holds a dataset of dstenv {maker}, not of generate; "
                                "use another --out")
        known = {e["file"]: e.get("sha256", "") for e in listed["shards"]}
    planned = {(out / t.file).resolve() for t in tasks}
    strays = [p for p in scan_shards(out) if p.resolve() not in planned]
    if strays:
        raise GenerateError(f"{out} holds shards that are not part of this run "
                            f"({strays[0].relative_to(out)}...{_made_with(strays[0], tasks)}); "
                            "use another --out")
    done, todo = {}, []
    for task in tasks:
        entry = _existing(out, task, known.get(task.file, ""))
        if entry is None:
            todo.append(task)
        else:
            done[task.file] = entry
    return done, todo
