"""Training a learned segmenter: Adam, weighted CE / Lovasz, atomic resumable checkpoints.

:func:`train` fits a network from :data:`dstenv.segment.models.MODELS` on a
dataset of ``{"x", "labels", "visible"}`` dicts (``dstenv.data.ShardDataset`` or
a streaming ``IterableDataset``). After every epoch it writes ``last.pt`` (model,
optimizer, epoch, torch RNG state, history, configuration) and, when the
validation mIoU improves, ``best.pt`` (first); both atomically. Calling it again with the
same output directory resumes after the last finished epoch and gives the same
weights as an uninterrupted run (on CPU): batch order and crops come from a
generator seeded by ``(seed, epoch)``, dropout from the restored torch RNG.
"""

from __future__ import annotations


import math
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from dstenv.config import ConfigError, merge_config
from dstenv.data.datasets import INPUT_CHANNELS, LABELS
from dstenv.segment.augment import random_crop, random_flip
from dstenv.dst.frame import CLASSES
from dstenv.io import file_sha256
from dstenv.segment.checkpoint import (json_ready, load_checkpoint, network_checkpoint,
                                       save_checkpoint)
from dstenv.segment.losses import LOSSES, build_loss, class_statistics, median_frequency_weights
from dstenv.segment.metrics import ConfusionMeter, iou_per_class, mean_iou
from dstenv.segment.models import MODELS
from dstenv.segment.segmenters import TorchSegmenter

__all__ = ["check_train_config", "default_train_config", "train", "resolve_device"]


def default_train_config() -> dict[str, Any]:
    """Every training option with its default (override with :func:`dstenv.config.merge_config`)."""
    return {
        "model": "unet-light",  # key of dstenv.segment.models.MODELS
        "model_kwargs": {},  # builder options, e.g. {"base": 16}
        "loss": "wce+lovasz",  # one of dstenv.segment.losses.LOSSES
        "class_weights": None,  # list of 5 floats; None: median frequency of the training data
        "weight_power": 1.0,  # median-frequency weights ** this (1: paper eq. 2; 0: unweighted)
        "epochs": 10,
        "batch_size": 8,
        "lr": 1e-3,  # Adam learning rate (betas 0.9/0.999, eps 1e-8 as in the paper)
        "weight_decay": 0.0,
        "crop": 0,  # [cells] side of random square training crops; 0: whole grids
        # probability that a training sample is mirrored left-right (its columns, across
        # the ego's heading: the grid's axes, dstenv.grid); 0: off (no random draw)
        "flip": 0.0,
        "max_batches": 0,  # training batches per epoch; 0: the whole dataset (required for streams)
        # training batches per epoch drawn with replacement, whatever the data size (the
        # same optimiser steps for 140 or 14000 frames: the training-set-size curve); 0: off
        "fixed_batches": 0,
        "seed": 0,
        "device": "cpu",  # "cpu", "cuda" or "auto"
        "num_workers": 0,  # DataLoader workers
        "init": "",  # checkpoint whose weights start the training (fine-tuning); "" = random
        # what the data's "x" holds (dstenv.data.datasets.INPUTS) and its label convention
        # (LABELS): recorded with the network; the caller's datasets must match them
        "inputs": "fcn10",
        "labels": "full",
    }


def resolve_device(name: str) -> torch.device:
    """``"auto"`` -> CUDA when available, else CPU; otherwise ``torch.device(name)``."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name.startswith("cuda") and not torch.cuda.is_available():
        raise ConfigError(f"device {name!r} requested but CUDA is not available")
    try:
        return torch.device(name)
    except RuntimeError:  # torch's message is several lines
        raise ConfigError(f"device {name!r}: not a torch device; use auto, cpu or cuda") from None


def check_train_config(config: Mapping[str, Any]) -> dict[str, Any]:
    """``config`` over :func:`default_train_config`, checked: the config :func:`train`
    runs with, or one ConfigError naming the ``train.`` key (before any data is read)."""
    cfg = merge_config(default_train_config(), dict(config), where="train")
    _check(cfg)
    return cfg


def _check(cfg: dict[str, Any]) -> None:
    if cfg["model"] not in MODELS:
        raise ConfigError(
            f"train.model: unknown model {cfg['model']!r}; choose from {', '.join(MODELS)}"
        )
    if cfg["loss"] not in LOSSES:
        raise ConfigError(
            f"train.loss: unknown loss {cfg['loss']!r}; choose from {', '.join(LOSSES)}"
        )
    if cfg["inputs"] not in INPUT_CHANNELS:
        raise ConfigError(f"train.inputs: unknown inputs {cfg['inputs']!r}; choose from "
                          f"{', '.join(INPUT_CHANNELS)}")
    if cfg["labels"] not in LABELS:
        raise ConfigError(f"train.labels: unknown labels {cfg['labels']!r}; choose from "
                          f"{', '.join(LABELS)}")
    for key in ("epochs", "batch_size"):
        if cfg[key] < 1:
            raise ConfigError(f"train.{key}: must be >= 1, got {cfg[key]}")
    # each written as "not ..." so that NaN fails too; the first bad key is named
    rules = (("crop", lambda v: v >= 0, "an integer >= 0 (0: no crop)"),
             ("max_batches", lambda v: v >= 0, ">= 0 (0: every batch)"),
             ("fixed_batches", lambda v: v >= 0, ">= 0"),
             ("lr", lambda v: v > 0 and math.isfinite(v), "a finite number > 0"),
             ("weight_power", lambda v: v >= 0 and math.isfinite(v), "a finite number >= 0"),
             ("flip", lambda v: 0 <= v <= 1, "in [0, 1]"))
    for key, ok, what in rules:
        if not ok(cfg[key]):
            raise ConfigError(f"train.{key} must be {what}, got {cfg[key]}")
    w = cfg["class_weights"]
    if w is not None and (not all(isinstance(v, (int, float)) and math.isfinite(v) and v >= 0
                                  for v in w) or not any(v > 0 for v in w)):
        raise ConfigError(f"train.class_weights: {list(w)}: need finite values >= 0, not all 0")


def _class_weights(
    cfg: dict[str, Any], data: Any, log: Callable[[str], None]
) -> list[float] | None:
    if not cfg["loss"].startswith("wce"):
        return None
    if cfg["class_weights"] is not None:
        if len(cfg["class_weights"]) != len(CLASSES):
            raise ConfigError(
                f"train.class_weights: need {len(CLASSES)} values, got {len(cfg['class_weights'])}"
            )
        return [float(w) for w in cfg["class_weights"]]
    if isinstance(data, torch.utils.data.IterableDataset):
        raise ConfigError("train.class_weights must be given for a streaming dataset")
    loader = torch.utils.data.DataLoader(data, batch_size=16, num_workers=cfg["num_workers"])
    counts, present = class_statistics((b["labels"] for b in loader), len(CLASSES))
    weights = median_frequency_weights(counts, present) ** float(cfg["weight_power"])
    log(
        f"class weights (median frequency ^ {cfg['weight_power']:g}): "
        + ", ".join(f"{n} {w:.3g}" for n, w in zip(CLASSES, weights))
    )
    return [float(w) for w in weights]


def train(
    config: Mapping[str, Any],
    train_data: Any,
    val_data: Any = None,
    out_dir: str | Path | None = None,
    resume: bool = True,
    progress: bool = True,
    log: Callable[[str], None] = print,
    data_id: Mapping[str, Any] | None = None,
) -> tuple[TorchSegmenter, dict[str, Any]]:
    """Train a network.

    Args:
        config: overrides of :func:`default_train_config`.
        train_data: map-style or iterable dataset of ``{"x": (C, H, W) float32,
            "labels": (H, W) int64, "visible": (H, W) bool}``.
        val_data: optional map-style dataset scored after every epoch.
        out_dir: where ``last.pt``/``best.pt`` go; ``None`` keeps nothing on disk.
        resume: continue from ``out_dir/last.pt`` if it exists.
        progress: tqdm bars.
        log: receives one-line messages.
        data_id: JSON-compatible identity of the training data
            (:func:`dstenv.segment.checkpoint.training_data`),
            kept in the checkpoints: resuming on other data is refused.

    Returns:
        ``(segmenter, history)``: the trained network (weights of the last epoch) and
        ``{"epoch", "train_loss", "val_loss", "val_miou", "val_iou"}`` lists.
    """
    cfg = check_train_config(config)
    device = resolve_device(cfg["device"])
    streaming = isinstance(train_data, torch.utils.data.IterableDataset)
    if streaming and cfg["max_batches"] < 1:
        raise ConfigError("train.max_batches must be > 0 for a streaming dataset (it has no end)")
    sample = next(iter(train_data)) if streaming else train_data[0]
    in_channels = int(sample["x"].shape[0])
    if in_channels != INPUT_CHANNELS[cfg["inputs"]]:
        raise ConfigError(f"train.inputs is {cfg['inputs']!r} ({INPUT_CHANNELS[cfg['inputs']]} "
                          f"channels) but the training data gives {in_channels}")

    out = Path(out_dir) if out_dir is not None else None
    last = out / "last.pt" if out else None
    ckpt = None
    if resume and last is not None and last.exists():
        try:
            ckpt = load_checkpoint(last)
        except ValueError as exc:  # a damaged last.pt: say how to start over
            raise ValueError(f"{exc}; start over with --no-resume (resume=False)") from None
    init_digest = file_sha256(cfg["init"]) if cfg["init"] else ""
    if ckpt is not None:
        # options added since the checkpoint was written count as their defaults
        free = ("epochs", "class_weights", "num_workers")  # workers: the same batches
        saved = {k: v for k, v in {**default_train_config(), **ckpt["config"]}.items()
                 if k not in free}
        mine = {k: v for k, v in cfg.items() if k not in free}
        given = cfg["class_weights"]  # None: computed from the data, then kept
        if given is not None and json_ready(given) != ckpt["config"]["class_weights"]:
            mine["class_weights"] = given  # named in the refusal below
        if ckpt.get("init_sha256") and init_digest:  # the starting weights, wherever they lie
            if ckpt["init_sha256"] != init_digest:
                raise ConfigError(f"{last}: checkpoint started from other weights than "
                                  f"train.init {cfg['init']} holds now (it changed since); "
                                  "use another output directory or --no-resume")
            saved["init"] = mine["init"]
        if saved != mine:
            diff = sorted(k for k in mine if saved.get(k) != mine[k])
            raise ConfigError(f"{last}: checkpoint was trained with other settings "
                              f"({', '.join(diff)}); use another output directory or --no-resume")
        theirs = ckpt.get("data")  # checkpoints before 2026-12-07 carry none
        # the keys it recorded (a stream's cell_size, added later, follows its config hash)
        ours = json_ready(data_id) if data_id is not None else None
        diff = sorted(k for k in (theirs or {}) if ours is not None and k != "source"
                      and theirs[k] != ours.get(k))  # the folder's name: a copy resumes
        if diff:
            raise ConfigError(
                f"{last}: checkpoint was trained on other data ({', '.join(diff)} differ: "
                f"{theirs.get('source', '?')}); give the same --data, another output "
                "directory or --no-resume")
        cfg["class_weights"] = ckpt["config"]["class_weights"]
    else:
        cfg["class_weights"] = _class_weights(cfg, train_data, log)

    torch.manual_seed(cfg["seed"])
    seg = TorchSegmenter(cfg["model"], cfg["model_kwargs"], in_channels, len(CLASSES), device,
                         cfg["inputs"])
    model = seg.model
    if cfg["init"] and ckpt is None:
        try:
            model.load_state_dict(_init_weights(cfg, seg))
        except RuntimeError as exc:  # keys or shapes that do not fit the spec's network
            first = (str(exc).strip().splitlines() or ["mismatch"])[-1].strip()
            raise ConfigError(f"train.init: {cfg['init']}: its weights do not fit a "
                              f"{cfg['model']}: {first}") from None
        log(f"starting from the weights of {cfg['init']}")
    weights = (
        None if cfg["class_weights"] is None else np.asarray(cfg["class_weights"], dtype=np.float32)
    )
    loss_fn = build_loss(cfg["loss"], weights).to(device)
    opt = torch.optim.Adam(
        model.parameters(),
        lr=cfg["lr"],
        betas=(0.9, 0.999),
        eps=1e-8,
        weight_decay=cfg["weight_decay"],
    )
    history: dict[str, list] = {k: [] for k in ("epoch", "train_loss", "val_loss", "val_miou",
                                                 "val_iou")}
    start = 0
    if ckpt is not None:
        model.load_state_dict(ckpt["model"])
        opt.load_state_dict(ckpt["optimizer"])
        history = ckpt["history"]
        start = int(ckpt["epoch"]) + 1
        torch.set_rng_state(ckpt["rng"]["torch"])
        log(f"resuming from {last} after epoch {start}")

    # best.pt: highest val mIoU, or lowest training loss without validation data
    best = max((m if m is not None else -loss for m, loss in
                zip(history["val_miou"], history["train_loss"])), default=-math.inf)
    for epoch in range(start, cfg["epochs"]):
        gen = torch.Generator().manual_seed(cfg["seed"] * 100_003 + epoch)
        if hasattr(train_data, "set_epoch"):  # streaming: a new episode stream per epoch
            train_data.set_epoch(epoch)
        fixed = cfg["fixed_batches"] if not streaming else 0
        sampler = torch.utils.data.RandomSampler(
            train_data, replacement=True, num_samples=fixed * cfg["batch_size"], generator=gen
        ) if fixed else None
        loader = torch.utils.data.DataLoader(
            train_data,
            batch_size=cfg["batch_size"],
            shuffle=not streaming and sampler is None,
            sampler=sampler,
            generator=gen if sampler is None else None,
            num_workers=cfg["num_workers"],
            drop_last=False,
        )
        n_batches = len(loader) if not streaming else cfg["max_batches"]
        if cfg["max_batches"]:
            n_batches = min(n_batches, cfg["max_batches"])
        model.train()
        total, count = 0.0, 0
        bar = tqdm(loader, total=n_batches, desc=f"epoch {epoch + 1}/{cfg['epochs']}",
                   disable=not progress, leave=False)
        for b, batch in enumerate(bar):
            if b >= n_batches:
                break
            batch = random_flip(random_crop(batch, cfg["crop"], gen), cfg["flip"], gen)
            x = batch["x"].to(device).float()
            y = batch["labels"].to(device).long()
            loss = loss_fn(model(x), y)
            if not math.isfinite(value := float(loss.detach())):  # before the step: no NaN
                raise ValueError(  # weights, and no checkpoint of them
                    f"train: the loss is {value} at epoch {epoch + 1}, batch {b + 1}: an "
                    "input holds NaN or inf (check the data: dstenv info --verify frames) "
                    "or the learning rate (train.lr, --lr) is too high")
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            total += value
            count += 1
            bar.set_postfix(loss=f"{total / count:.4f}")
        bar.close()
        val_loss, val_miou, val_iou = _validate(model, loss_fn, val_data, cfg, device)
        history["epoch"].append(epoch + 1)
        history["train_loss"].append(total / max(count, 1))
        history["val_loss"].append(val_loss)
        history["val_miou"].append(val_miou)
        history["val_iou"].append(val_iou)
        log(
            f"epoch {epoch + 1}: train loss {total / max(count, 1):.4f}"
            + (
                f", val loss {val_loss:.4f}, val mIoU {val_miou:.3f}"
                if val_miou is not None
                else ""
            )
        )
        if out is not None:
            payload = {
                "spec": seg.spec(),
                "model": model.state_dict(),
                "optimizer": opt.state_dict(),
                "epoch": epoch,
                "rng": {"torch": torch.get_rng_state()},
                "config": cfg,
                "history": history,
                **({"data": json_ready(data_id)} if data_id is not None else {}),
                **({"init_sha256": init_digest} if init_digest else {}),
            }
            score = val_miou if val_miou is not None else -(total / max(count, 1))
            if score > best:  # best.pt first: a run killed between the two files redoes
                best = score  # this epoch on resume (the same bytes) and writes both
                save_checkpoint(out / "best.pt", payload)
            save_checkpoint(last, payload)
    model.eval()
    return seg, history


def start_changed(out_dir: str | Path, init: str | Path) -> bool:
    """Whether ``out_dir/last.pt`` started from other weights than ``init`` holds now (by
    content; by path before 2026-12-07); ``False`` when there is nothing to resume."""
    last = Path(out_dir) / "last.pt"
    if not last.exists():
        return False
    ckpt = load_checkpoint(last)
    digest = ckpt.get("init_sha256")
    return digest != file_sha256(init) if digest else ckpt["config"].get("init") != str(init)


def _init_weights(cfg: dict[str, Any], seg: TorchSegmenter) -> dict[str, Any]:
    """The state dict of ``cfg["init"]``, checked against the network being trained."""
    init = network_checkpoint(cfg["init"], "train.init")  # ValueError: one line
    spec = {"inputs": "fcn10", **init["spec"]}  # written before inputs were recorded
    if spec != seg.spec():
        diff = sorted(k for k in seg.spec() if spec.get(k) != seg.spec()[k])
        raise ConfigError(f"train.init: {cfg['init']} holds another network ({', '.join(diff)} "
                          f"differ: { {k: spec.get(k) for k in diff} }); train the same model "
                          "and inputs")
    return init["model"]


@torch.no_grad()
def _validate(
    model, loss_fn, val_data, cfg, device
) -> tuple[float | None, float | None, list | None]:
    if val_data is None:
        return None, None, None
    model.eval()
    meter = ConfusionMeter(len(CLASSES))
    total, count = 0.0, 0
    loader = torch.utils.data.DataLoader(
        val_data, batch_size=cfg["batch_size"], num_workers=cfg["num_workers"]
    )
    for batch in loader:
        x = batch["x"].to(device).float()
        y = batch["labels"].to(device).long()
        logits = model(x)
        total += float(loss_fn(logits, y))
        count += 1
        meter.update(logits.argmax(1).cpu(), y.cpu())
    iou = [None if np.isnan(v) else float(v) for v in iou_per_class(meter.all)]
    miou = mean_iou(meter.all)
    return total / max(count, 1), (None if np.isnan(miou) else miou), iou
