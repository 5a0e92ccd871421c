"""The networks of a benchmark plan (:mod:`dstenv.segment.plan`).

:func:`plan_networks` trains each model of ``models`` once per seed of
``train_seeds`` (``best.pt`` picked on validation), after the recorded search of
``search.key`` over ``search.values`` on validation drives when one is set; adds the
training-set-size curve (``curve.frames``: the same model on the first N training
frames); and, with ``no_map.epochs``, fine-tunes each trained network on the training
drives fused without a map.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch

from dstenv.config import ConfigError
from dstenv.segment.plan import Plan, split_drives

__all__ = ["plan_networks"]


def _subset(ds: Any, n: int, seed: int) -> Any:
    if n > len(ds):
        raise ConfigError(f"curve.frames: {n} training frames asked but the train split has "
                          f"{len(ds)}; raise data.frames")
    idx = np.random.default_rng(seed).permutation(len(ds))[:n]
    return torch.utils.data.Subset(ds, sorted(int(i) for i in idx))


def _search(cfg: Mapping[str, Any], datasets: Mapping[str, Any], device: torch.device,
            out: Path, progress: bool, log: Callable[[str], None]) -> dict[str, Any]:
    """Train one network per value of ``search.key``; pick the best on validation drives.

    The score is the mIoU over the headline scope of the replayed validation drives
    (never the test split), the same :func:`dstenv.segment.score.score` as the report.
    """
    from dstenv.segment.checkpoint import load_segmenter
    from dstenv.segment.results import HEADLINE
    from dstenv.segment.score import score
    from dstenv.segment.stats import miou_batch
    from dstenv.segment.train import train

    if not len(datasets["val"]):
        raise ConfigError("search: needs a validation split (raise data.frames)")
    key, model, seed = cfg["search"]["key"], cfg["models"][0], cfg["train_seeds"][0]
    val = split_drives(datasets["val"], False, progress, log)
    rows = []
    for value in cfg["search"]["values"]:
        tcfg = {**cfg["train"], key: value, "model": model, "seed": seed, "device": str(device),
                "model_kwargs": cfg["model_kwargs"].get(model, {})}
        mdir = out / "search" / f"{model}-{key}-{value}"
        train(tcfg, datasets["train"], datasets["val"], mdir, progress=progress, log=log)
        seg = load_segmenter(mdir / "best.pt", device)
        cm = score([seg], val.episodes, val.generation_params).confusion[seg.label][HEADLINE]
        rows.append({"value": value, "val_miou": float(miou_batch(cm.sum(0)))})
        log(f"search {key}={value}: validation mIoU ({HEADLINE}) {rows[-1]['val_miou']:.3f}")
    best = max(rows, key=lambda r: r["val_miou"])
    return {"key": f"train.{key}", "model": model, "seed": seed, "scope": HEADLINE,
            "validation_drives": len(val.episodes), "evaluations": rows, "chosen": best["value"]}


def plan_networks(cfg: Mapping[str, Any], datasets: Mapping[str, Any], device: torch.device,
                  out: Path, plan: Plan, progress: bool, log: Callable[[str], None],
                  timings: dict[str, float]) -> None:
    """Train the networks of ``cfg`` into ``plan`` (module docstring); ``timings``
    receives each training's duration [s]."""
    from dstenv.segment.checkpoint import load_segmenter
    from dstenv.segment.train import train

    val = datasets["val"] if len(datasets["val"]) else None
    seeds = list(cfg["train_seeds"])
    if cfg["search"]["values"] and cfg["models"]:
        t = time.perf_counter()
        plan.search = _search(cfg, datasets, device, out, progress, log)
        cfg = {**cfg, "train": {**cfg["train"], cfg["search"]["key"]: plan.search["chosen"]}}
        timings["search_s"] = time.perf_counter() - t
    runs = [(name, s, None) for name in cfg["models"] for s in seeds]
    runs += [(cfg["curve"]["model"], seeds[0], int(n)) for n in cfg["curve"]["frames"]]
    for name, seed, n in runs:
        t = time.perf_counter()
        tcfg = dict(cfg["train"])
        tcfg.update(model=name, model_kwargs=cfg["model_kwargs"].get(name, {}),
                    device=str(device), seed=seed)
        if n is not None:
            label, mdir, data = f"{name} [{n} train frames]", out / "curve" / f"{name}-{n}", \
                _subset(datasets["train"], n, 0)
        elif len(seeds) == 1:
            label, mdir, data = name, out / "models" / name, datasets["train"]
        else:
            label, mdir, data = (f"{name} (seed {seed})", out / "models" / name / f"seed{seed}",
                                 datasets["train"])
        _, plan.histories[label] = train(tcfg, data, val, mdir, progress=progress, log=log)
        timings[f"train_{label}_s"] = time.perf_counter() - t
        seg = load_segmenter(mdir / "best.pt", device)
        seg.label = label
        plan.add(seg, "learned", {**seg.describe(), "seed": seed, "checkpoint": str(mdir)})
        if n is not None:
            plan.curve[label] = n
            continue
        if len(seeds) > 1:
            plan.seed_groups.setdefault(name, []).append(label)
        if cfg["no_map"]["epochs"]:
            _no_map_network(cfg, datasets, tcfg, name, seed, len(seeds) > 1, mdir, plan,
                            progress, log, timings)


def _no_map_network(cfg: Mapping[str, Any], datasets: Mapping[str, Any],
                    tcfg: dict[str, Any], name: str, seed: int, seeded: bool, init: Path,
                    plan: Plan, progress: bool, log: Callable[[str], None],
                    timings: dict[str, float]) -> None:
    """Fine-tune one trained network on the training frames fused without a map."""
    from dstenv.segment.checkpoint import load_segmenter
    from dstenv.segment.train import start_changed, train

    subsets = {}
    for split in ("train", "val"):
        idx = datasets[split].no_map_indices() if len(datasets[split]) else []
        subsets[split] = torch.utils.data.Subset(datasets[split], idx) if idx else None
    group = f"{name} no-map"
    if subsets["train"] is None:  # e.g. --data of a plain `dstenv generate` (map everywhere)
        plan.unscored[group] = (
            "no training drive was fused without a map, so there is no map-free network "
            "to train (data generated with gis.no_map_prob > 0 has some; without --data: "
            "data.overrides.gis.no_map_prob; no_map.epochs=0 skips it)")
        return
    t = time.perf_counter()
    label = f"{group} (seed {seed})" if seeded else group
    mdir = init.parent / f"{init.name}-no-map" if not seeded else \
        init.parent.parent / f"{name}-no-map" / init.name
    ncfg = {**tcfg, "init": str(init / "best.pt"), "epochs": int(cfg["no_map"]["epochs"]),
            "lr": float(cfg["no_map"]["lr"]), "fixed_batches": 0}
    fresh = start_changed(mdir, init / "best.pt")  # its start was trained further since
    log(f"{label}: fine-tuning on {len(subsets['train'])} training frames without a map"
        + (" (again: its starting network changed since)" if fresh else ""))
    _, plan.histories[label] = train(ncfg, subsets["train"], subsets["val"], mdir,
                                     progress=progress, log=log, resume=not fresh)
    timings[f"train_{label}_s"] = time.perf_counter() - t
    seg = load_segmenter(mdir / "best.pt", torch.device(tcfg["device"]))
    seg.label = label
    plan.add(seg, "learned", {**seg.describe(), "seed": seed, "checkpoint": str(mdir),
                              "init": str(init / "best.pt"),
                              "no_map_frames": len(subsets["train"])})
    if seeded:
        plan.seed_groups.setdefault(group, []).append(label)
