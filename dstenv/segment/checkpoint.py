"""Checkpoints: written atomically, read with ``torch.load(..., weights_only=True)``.

A checkpoint is a dict of tensors and JSON-compatible data only (no pickled
classes), so loading never executes code from the file::

    {"format": "dstenv-segmenter", "version": 1,
     "spec": {"model", "model_kwargs", "in_channels", "num_classes"},
     "model": state_dict, "optimizer": state_dict | None, "epoch": int,
     "rng": {"torch": ByteTensor}, "config": {...}, "history": {...},
     "decision": {...} (optional: a decision rule, dstenv.segment.decide)}

An ensemble (:class:`~dstenv.segment.segmenters.EnsembleSegmenter`, written by
:func:`dstenv.segment.decide.decide_ensemble`) is one file too::

    {"format": ..., "version": 1, "decision": {...} | None,
     "ensemble": [{"spec", "model", "data", "source": path, "sha256": hex}, ...]}
"""

from __future__ import annotations

import errno
import hashlib
import json
import shutil
import zipfile
from pathlib import Path
from typing import Any

import torch

from dstenv.io import atomic_path
from dstenv.segment.segmenters import EnsembleSegmenter, TorchSegmenter

__all__ = ["FORMAT", "save_checkpoint", "load_checkpoint", "network_checkpoint",
           "load_segmenter", "segmenter_of", "training_data",
           "json_ready", "read_weights"]

FORMAT = "dstenv-segmenter"
_VERSION = 1


def save_checkpoint(path: str | Path, payload: dict[str, Any]) -> Path:
    """Write ``payload`` (plus format tags) to ``path`` via a temporary file and rename.

    A killed process leaves either the previous file or the new one, never half.
    """
    path = Path(path)
    try:
        with atomic_path(path) as tmp:
            torch.save({"format": FORMAT, "version": _VERSION, **payload}, tmp)
    except RuntimeError as exc:  # torch's zip writer reports a full disk this way
        try:  # (its text, "[enforce fail at inline_container.cc:672] . unexpected pos",
            free = shutil.disk_usage(path.parent).free  # named no cause)
        except OSError:
            free = -1
        if 0 <= free < 64 << 20:
            raise OSError(errno.ENOSPC, f"cannot write the checkpoint: the disk is full "
                          f"({free >> 10} KiB free)", str(path)) from None
        first = (str(exc).strip().splitlines() or ["write failed"])[0]
        raise OSError(f"{path}: cannot write the checkpoint ({first})") from None
    return path


def read_weights(path: str | Path, what: str) -> Any:
    """``torch.load`` of a file of tensors only (``weights_only``, on the CPU), so loading
    never runs code from it.

    Raises:
        ValueError: one line ``"PATH: WHAT[ (the file is empty)]: <torch's first line>"``
            for a file torch cannot read (torch raises many exception types).
    """
    path = Path(path)
    try:
        with zipfile.ZipFile(path) as archive:  # torch.load skips the entries' CRC-32s
            bad = archive.testzip()
    except (zipfile.BadZipFile, OSError, EOFError):
        bad = None  # not a zip, unreadable: torch.load below names it
    if bad is not None:
        raise ValueError(f"{path}: {what}: damaged ({bad} fails its checksum); train it "
                         "again or restore the file")
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - torch raises many types for bad files
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        if path.stat().st_size == 0:
            first = "the file is empty"
        elif not zipfile.is_zipfile(path):  # torch.save writes a zip archive
            first = "not a PyTorch file (torch.save writes a zip archive)"
        elif first.startswith("Weights only load failed"):  # not its advice to run code
            first = "it holds objects other than tensors; refused (loading them runs code)"
        raise ValueError(f"{path}: {what}: {first}") from None


def load_checkpoint(path: str | Path) -> dict[str, Any]:
    """Read a checkpoint written by :func:`save_checkpoint` (weights only, on CPU).

    Raises:
        FileNotFoundError: no such file.
        ValueError: not a dstenv segmenter checkpoint, or unreadable.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"checkpoint not found: {path}")
    ckpt = read_weights(path, "cannot read checkpoint")
    if not isinstance(ckpt, dict) or ckpt.get("format") != FORMAT:
        raise ValueError(f"{path}: not a dstenv segmenter checkpoint")
    if ckpt.get("version") != _VERSION:
        raise ValueError(
            f"{path}: checkpoint version {ckpt.get('version')} not supported (need {_VERSION})"
        )
    return ckpt


def network_checkpoint(path: str | Path, what: str) -> dict[str, Any]:
    """:func:`load_checkpoint` of one network's file (what ``what``, e.g. ``"--init"``,
    needs: its ``spec`` and weights); an ensemble's is refused, naming its members' files.

    Raises:
        ValueError: one line naming ``what`` and ``path``.
    """
    ckpt = load_checkpoint(path)
    if ckpt.get("ensemble") is not None:
        members = _members(ckpt["ensemble"], path)
        sources = [str(m["source"]) for m in members if isinstance(m.get("source"), str)]
        raise ValueError(f"{what} {path}: an ensemble of {len(members)} networks, not one; "
                         + (f"use one of its members: {', '.join(sources)}" if sources else
                            "use one of the networks it was made of"))
    if not isinstance(ckpt.get("spec"), dict) or not isinstance(ckpt.get("model"), dict):
        raise ValueError(f"{what} {path}: checkpoint has no valid 'spec' and weights; was it "
                         "written by dstenv train?")
    return ckpt


def _members(value: Any, path: str | Path) -> list[dict[str, Any]]:
    """An ensemble checkpoint's ``"ensemble"`` entry, checked: two or more dicts."""
    if not isinstance(value, list) or len(value) < 2 or not all(isinstance(m, dict)
                                                                for m in value):
        raise ValueError(f"{path}: 'ensemble' must list two or more networks; write it with "
                         "dstenv.segment.decide.decide_ensemble")
    return value


_SPEC_KEYS = {"model": str, "model_kwargs": dict, "in_channels": int, "num_classes": int}


def load_segmenter(path: str | Path, device: str | torch.device = "cpu"
                   ) -> TorchSegmenter | EnsembleSegmenter:
    """Rebuild the network of a checkpoint (or the networks of an ensemble's) and load
    its weights (eval mode), with the checkpoint's decision rule.

    Raises:
        ValueError: unreadable file, a missing or malformed ``spec``, or weights that
            do not fit the network the spec describes (naming the file).
    """
    return segmenter_of(load_checkpoint(path), path, device)


def segmenter_of(ckpt: dict[str, Any], path: str | Path, device: str | torch.device = "cpu"
                 ) -> TorchSegmenter | EnsembleSegmenter:
    """:func:`load_segmenter` of a checkpoint already read from ``path`` (named in errors);
    ``ckpt`` is left as it is."""
    members = ckpt.get("ensemble")
    seg: TorchSegmenter | EnsembleSegmenter
    if members is not None:
        members = _members(members, path)
        nets = [_network(m, f"{path} (ensemble member {i})", device)
                for i, m in enumerate(members)]
        for i, (net, m) in enumerate(zip(nets, members)):
            net.label = str(m.get("source", f"member {i}"))
            net.trained_cell_size = _cell_size(m)
        try:
            seg = EnsembleSegmenter(nets)
        except ValueError as exc:
            raise ValueError(f"{path}: {exc}") from None
        seg.sources = [{"source": m.get("source"), "sha256": m.get("sha256")} for m in members]
    else:
        seg = _network(ckpt, str(path), device)
        seg.trained_cell_size = _cell_size(ckpt)
    if ckpt.get("decision") is not None:  # a decision rule (dstenv.segment.decide)
        from dstenv.segment.decide import check_decision, decision_name

        seg.decision = check_decision(ckpt["decision"], seg.inputs, str(path))
        seg.label = f"{seg.label}, {decision_name(seg.decision)}"
    return seg


def _cell_size(entry: dict[str, Any]) -> float | None:
    """The cells [m] a network was trained on, when its checkpoint says (``dstenv train``
    since 2026-12-07)."""
    data = entry.get("data")
    return data.get("cell_size") if isinstance(data, dict) else None


def _network(entry: dict[str, Any], where: str, device: str | torch.device) -> TorchSegmenter:
    """The network of one checkpoint entry (``spec`` and ``model``); ``where`` names it."""
    spec = entry.get("spec")
    if not isinstance(spec, dict) or not all(isinstance(spec.get(k), t)
                                             for k, t in _SPEC_KEYS.items()):
        raise ValueError(f"{where}: checkpoint has no valid 'spec' (needs "
                         f"{', '.join(_SPEC_KEYS)}); was it written by dstenv train?")
    if not isinstance(entry.get("model"), dict):
        raise ValueError(f"{where}: checkpoint holds no model weights")
    seg = TorchSegmenter(spec["model"], spec["model_kwargs"], spec["in_channels"],
                         spec["num_classes"], device, str(spec.get("inputs", "fcn10")))
    try:
        seg.model.load_state_dict(entry["model"])
    except RuntimeError as exc:
        first = (str(exc).strip().splitlines() or ["mismatch"])[0]
        raise ValueError(f"{where}: weights do not fit a {spec['model']} with "
                         f"{spec['in_channels']} input channels: {first}") from None
    seg.model.eval()
    return seg


def json_ready(value: Any) -> Any:
    """``value`` as JSON stores it (tuples become lists), for comparisons with saved data."""
    return json.loads(json.dumps(value))


def training_data(dataset: Any) -> dict[str, Any]:
    """What training data a checkpoint was made on (kept in it, compared on resume),
    cheaply: for shards (:class:`dstenv.data.ShardDataset`) the folder's name, each shard
    file's name and size, the frames and the cell size [m]; for a stream
    (:class:`dstenv.data.StreamingDataset`) a hash of its configuration, its seed, split
    and frame sampling. (A whole dataset folder's identity, which the benchmark keeps, is
    :func:`dstenv.data.manifest.data_identity`.)"""
    files = getattr(dataset, "files", None)
    if files is not None:
        cell = getattr(dataset, "cell_size", None)
        return {"source": f"shards in {Path(files[0]).parent.parent.name}" if files else
                "no shards", "frames": len(dataset), "cell_size": cell,
                "shards": [[f"{Path(f).parent.name}/{Path(f).name}", Path(f).stat().st_size]
                           for f in files]}
    cfg = getattr(dataset, "config", None)
    config = json.dumps(cfg, sort_keys=True, default=str)
    cell = cfg.get("grid", {}).get("cell_size") if isinstance(cfg, dict) else None
    return {"source": "stream", "config": hashlib.sha256(config.encode()).hexdigest()[:16],
            "cell_size": cell, **{k: getattr(dataset, k, None)
                                  for k in ("seed", "split", "episode_length", "stride", "warmup")}}
