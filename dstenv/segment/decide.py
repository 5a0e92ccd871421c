"""A network's decision rule: from class scores to one class per cell.

A trained network's ``argmax`` is one decision rule among several. Two others,
both chosen without a real frame, matter for the sim-only networks on KITTI
(``real_net``, docs/benchmark.md, "A decision rule chosen on the simulated drives"):

* **The static/moving offset.** Among cells whose ``argmax`` is ``static`` or
  ``moving``, the cell is ``moving`` iff ``logit(moving) + offset > logit(static)``.
  Training seeds differ most in how readily they call a still object moving; the
  offset that minimises the *static/moving confusion* on the simulated validation
  drives (the share of visible static cells called moving plus the share of visible
  moving cells called static, KITTI's label convention) corrects each seed's lean
  (:func:`calibrate_offset`). It never turns an object cell into ground or back.
* **The free-space rule** (:func:`~dstenv.segment.segmenters.free_space_veto`): no
  obstacle where the current sweep saw free space (the input's seen-free channel,
  ``fcn10+sensor`` and ``fcn10+sensor+past``).

A decision is a small dict kept in the checkpoint (``"decision"``), so a decided network
loads and scores anywhere a checkpoint does (:func:`decide_checkpoint`; an ensemble of
networks with a decision chosen on its mean scores: :func:`decide_ensemble`)::

    {"moving_offset": float, "free_veto": bool, "chosen_on": str,
     "confusion": {"offsets": [...], "values": [...]}}
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch

from dstenv.dst.frame import CLASSES

__all__ = ["OFFSETS", "SENSOR_INPUTS", "check_decision", "apply_decision", "offset_confusion",
           "calibrate_offset", "decide_checkpoint", "decide_ensemble", "decision_name"]

#: candidate static/moving offsets [logits]
OFFSETS: tuple[float, ...] = tuple(float(x) for x in np.round(np.arange(-4.0, 4.001, 0.25), 2))
#: inputs whose channel 10 is the current sweep's seen-free grid (the free-space rule)
SENSOR_INPUTS: tuple[str, ...] = ("fcn10+sensor", "fcn10+sensor+past")
_STATIC, _MOVING = CLASSES.index("static"), CLASSES.index("moving")
_FREE_CHANNEL = 10


def check_decision(decision: Any, inputs: str, where: str) -> dict[str, Any]:
    """``decision`` checked against the network's ``inputs``; ``where`` names it in errors.

    Raises:
        ValueError: one line naming ``where`` and the fix.
    """
    if not isinstance(decision, Mapping):
        raise ValueError(f"{where}: decision must be a dict with moving_offset and free_veto")
    off, veto = decision.get("moving_offset"), decision.get("free_veto")
    if isinstance(off, bool) or not isinstance(off, (int, float)) or not np.isfinite(off):
        raise ValueError(f"{where}: decision.moving_offset must be a finite number, got {off!r}")
    if not isinstance(veto, bool):
        raise ValueError(f"{where}: decision.free_veto must be true or false, got {veto!r}")
    if veto and inputs not in SENSOR_INPUTS:
        raise ValueError(f"{where}: decision.free_veto needs the current sweep in the input "
                         f"({' or '.join(SENSOR_INPUTS)}), this network reads {inputs!r}")
    return {**decision, "moving_offset": float(off)}


def decision_name(decision: Mapping[str, Any]) -> str:
    """A checked decision in a row label: ``"calibrated + free"`` for the benchmark's
    (an offset chosen on drives, the free-space rule), else what it does."""
    parts = (["calibrated"] if "chosen_on" in decision
             else [f"moving offset {float(decision['moving_offset']):+g}"])
    return " + ".join(parts + (["free"] if decision["free_veto"] else []))


def apply_decision(logits: torch.Tensor, x: torch.Tensor,
                   decision: Mapping[str, Any] | None) -> torch.Tensor:
    """Classes from ``logits (B, 5, H, W)`` and the input ``x (B, C, H, W)`` under
    ``decision`` (``None``: argmax): ``(B, H, W) int64``."""
    from dstenv.segment.segmenters import free_space_veto

    pred = logits.argmax(1)
    if decision is None:
        return pred
    off = float(decision["moving_offset"])
    if off != 0.0:
        obj = (pred == _STATIC) | (pred == _MOVING)
        moving = logits[:, _MOVING] + off > logits[:, _STATIC]
        pred = torch.where(obj, torch.where(moving, _MOVING, _STATIC), pred)
    if decision["free_veto"]:
        pred = free_space_veto(pred, x[:, :5], x[:, _FREE_CHANNEL] > 0.5)
    return pred


def offset_confusion(segmenter: Any, dataset: Any, offsets: tuple[float, ...] = OFFSETS,
                     batch_size: int = 8) -> np.ndarray:
    """The static/moving confusion (module doc) of ``segmenter`` for each offset:
    ``(len(offsets),) float64``.

    Args:
        segmenter: a :class:`~dstenv.segment.segmenters.TorchSegmenter`.
        dataset: samples ``{"x", "labels", "visible"}`` with KITTI's label convention
            (``ShardDataset(..., labels="kitti")``), the network's inputs.

    Raises:
        ValueError: no visible static or no visible moving cell in ``dataset``.
    """
    gaps: dict[int, list[np.ndarray]] = {_STATIC: [], _MOVING: []}
    cells = {_STATIC: 0, _MOVING: 0}
    for i in range(0, len(dataset), batch_size):
        batch = [dataset[j] for j in range(i, min(i + batch_size, len(dataset)))]
        x = torch.stack([torch.as_tensor(s["x"]) for s in batch])
        y = torch.stack([torch.as_tensor(s["labels"]) for s in batch])
        seen = torch.stack([torch.as_tensor(s["visible"]) for s in batch]).bool()
        logits = segmenter.logits(x)
        top = logits.argmax(1)
        obj = (top == _STATIC) | (top == _MOVING)
        gap = logits[:, _MOVING] - logits[:, _STATIC]
        for cls in (_STATIC, _MOVING):
            mask = (y == cls) & seen
            cells[cls] += int(mask.sum())
            gaps[cls].append(gap[mask & obj].numpy().astype(np.float64))
    if not cells[_STATIC] or not cells[_MOVING]:
        raise ValueError(f"no visible {'static' if not cells[_STATIC] else 'moving'} cell to "
                         "choose a static/moving offset on")
    g_s, g_m = (np.concatenate(gaps[c]) for c in (_STATIC, _MOVING))
    return np.array([np.count_nonzero(g_s + off > 0) / cells[_STATIC]
                     + np.count_nonzero(g_m + off <= 0) / cells[_MOVING] for off in offsets])


def calibrate_offset(segmenter: Any, dataset: Any, offsets: tuple[float, ...] = OFFSETS
                     ) -> tuple[float, np.ndarray]:
    """The offset with the least static/moving confusion on ``dataset`` (the first, i.e.
    the most negative, on ties) and the confusion of every offset."""
    conf = offset_confusion(segmenter, dataset, offsets)
    return float(offsets[int(np.argmin(conf))]), conf


def _decide(seg: Any, dataset: Any, chosen_on: str, free_veto: bool, where: str
            ) -> dict[str, Any]:
    """The decision of ``seg`` (its plain scores) calibrated on ``dataset``."""
    seg.decision = None  # calibrate the plain scores, whatever the file holds
    check_decision({"moving_offset": 0.0, "free_veto": bool(free_veto)}, seg.inputs, where)
    try:
        off, conf = calibrate_offset(seg, dataset)
    except ValueError as exc:
        raise ValueError(f"{where}: {exc} in {chosen_on}; calibrate on drives with both "
                         "(e.g. a larger validation split)") from None
    return check_decision({"moving_offset": off, "free_veto": bool(free_veto),
                           "chosen_on": chosen_on,
                           "confusion": {"offsets": list(OFFSETS),
                                         "values": [round(float(c), 6) for c in conf]}},
                          seg.inputs, where)


def decide_checkpoint(src: str | Path, dst: str | Path, dataset: Any, chosen_on: str,
                      free_veto: bool = True) -> dict[str, Any]:
    """Copy the checkpoint ``src`` to ``dst`` with a decision: the offset calibrated on
    ``dataset`` (:func:`calibrate_offset`; named ``chosen_on`` in the checkpoint) and the
    free-space rule if ``free_veto``. Returns the decision. ``dst`` is written
    atomically; ``src`` is left as it is."""
    from dstenv.segment.checkpoint import load_checkpoint, save_checkpoint, segmenter_of

    ckpt = load_checkpoint(src)  # read once: the network to calibrate, then the copy
    decision = _decide(segmenter_of(ckpt, src), dataset, chosen_on, free_veto, str(src))
    ckpt.pop("format", None)
    ckpt.pop("version", None)
    save_checkpoint(dst, {**ckpt, "decision": decision})
    return decision


def decide_ensemble(srcs: list[str | Path], dst: str | Path, dataset: Any, chosen_on: str,
                    free_veto: bool = True) -> dict[str, Any]:
    """Write to ``dst`` one checkpoint of the ensemble of the networks in ``srcs`` (the mean
    of their logits, :class:`~dstenv.segment.segmenters.EnsembleSegmenter`) with a decision
    calibrated on the ensemble's own scores, as :func:`decide_checkpoint` does for one
    network. Each member keeps its ``spec``, weights, training data and source (path
    and SHA-256). Returns the decision.

    Raises:
        ValueError: one line naming ``dst`` (or the member): fewer than two networks, a
            network twice, ``dst`` among them, an ensemble among them, networks of
            different inputs, classes or cells, or nothing to calibrate on
            (:func:`offset_confusion`). Nothing is written then.
    """
    from dstenv.io import file_sha256
    from dstenv.segment.checkpoint import network_checkpoint, save_checkpoint, segmenter_of
    from dstenv.segment.segmenters import EnsembleSegmenter

    if isinstance(srcs, (str, Path)) or len(srcs) < 2:
        raise ValueError(f"{dst}: an ensemble needs a list of two or more checkpoints, got "
                         f"{srcs!r}")
    if Path(dst).resolve() in {Path(src).resolve() for src in srcs}:
        raise ValueError(f"{dst}: is one of the ensemble's members; write the ensemble to "
                         "another file")
    ckpts = [network_checkpoint(src, f"{dst}: member") for src in srcs]  # one network each
    digests = [file_sha256(src) for src in srcs]
    twice = [str(src) for src, d in zip(srcs, digests) if digests.count(d) > 1]
    if twice:
        raise ValueError(f"{dst}: the same network twice among the members "
                         f"({', '.join(twice)}); list each network once")
    nets = [segmenter_of(ckpt, src) for ckpt, src in zip(ckpts, srcs)]
    for net, src in zip(nets, srcs):
        net.label = str(src)
    try:
        ens = EnsembleSegmenter(nets)
    except ValueError as exc:
        raise ValueError(f"{dst}: {exc}") from None
    decision = _decide(ens, dataset, chosen_on, free_veto, str(dst))
    members = [{"spec": ckpt["spec"], "model": ckpt["model"],
                **({"data": ckpt["data"]} if "data" in ckpt else {}),
                "source": str(src), "sha256": digest}
               for ckpt, src, digest in zip(ckpts, srcs, digests)]
    save_checkpoint(dst, {"ensemble": members, "decision": decision})
    return decision
