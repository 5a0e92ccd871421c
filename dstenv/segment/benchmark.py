"""``dstenv benchmark``: pure DST vs FCN-DST on held-out simulated maps.

Stages (each resumable: rerunning the same command reuses finished work):

1. **data** -- ``dstenv.data.generate`` writes train/val/test shards whose splits
   come from disjoint map seeds (:mod:`dstenv.data.sampling`), so the test maps
   are never seen in training or tuning.
2. **learned models** -- each network of ``models`` is trained on the train split
   (validation mIoU picks ``best.pt``) and scored on the stored test frames.
3. **DST** -- the test episodes are replayed once (:mod:`dstenv.segment.replay`),
   the replay is checked against the stored BetP, and every DST variant runs its
   own filter over the same inputs: ``dst`` for each preset in ``dst_presets``, and
   ``dst-tuned`` with parameters searched on replayed *training* episodes.
4. **report** -- ``results.json``, ``results.md`` and PNG figures in ``out``.

Every segmenter is scored on exactly the same frames (same episode seeds and
steps), over all labelled cells and over visible cells.

**Evaluation-only data** (``source = "kitti"`` shards of ``dstenv kitti convert``,
or shards without a train split) has no training split and cannot be replayed
through the simulator: :func:`run_benchmark` then scores the ``dst`` variant of the
generation parameters on the stored BetP, re-runs the filter over the stored
``sensor``/``gis``/``ego_pose`` for the other presets and ``tune.params`` only when
the shards hold every filtered frame (:func:`dstenv.segment.replay.stored_episodes`),
lists the variants it cannot score with the reason, and scores the given
checkpoints (e.g. trained on simulated data) instead of training models.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from dstenv.config import ConfigError, merge_config
from dstenv.dst.frame import CLASSES
from dstenv.dst.params import DSTParams
from dstenv.segment import report
from dstenv.segment.checkpoint import load_segmenter
from dstenv.segment.evaluate import batches, evaluate, load_checkpoints
from dstenv.segment.metrics import ConfusionMeter
from dstenv.segment.registry import create_segmenter
from dstenv.segment.replay import (
    Episode,
    check_replay,
    episode_targets,
    filter_episode,
    record_episodes,
    shard_attrs,
    split_index,
    stored_inputs,
)
from dstenv.segment.train import resolve_device, train

__all__ = ["PRESETS", "default_benchmark_config", "preset_config", "run_benchmark"]


def default_benchmark_config() -> dict[str, Any]:
    """Every benchmark option with its default (the ``cpu`` preset overrides some)."""
    return {
        "data": {
            "scenario": "",  # scenario name or .toml file; "" = default configuration
            "frames": 1000,  # total frames, split 80/10/10 train/val/test by map seed
            "seed": 0,
            "grid": 128,  # [cells] side of the square grid; 0 keeps the scenario's grid
            "episode_length": 200,  # [steps] of 0.1 s
            "stride": 10,  # keep one frame every `stride` steps
            "warmup": 10,  # [steps] first kept step
            "workers": 1,  # generation processes
            "frames_per_shard": 256,
        },
        "dst_presets": ["default", "paper"],  # DSTParams presets scored as `dst`
        "tune": {
            "enabled": True,  # add `dst-tuned`
            "episodes": 8,  # training episodes replayed for the search
            "budget": 30,  # parameter sets scored
            "seed": 0,
            # fixed dst-tuned parameters (DSTParams fields), e.g. those a simulated
            # benchmark found; {} = search them on the train split
            "params": {},
        },
        "models": ["unet-light"],  # learned segmenters to train (dstenv.segment.models.MODELS)
        "model_kwargs": {},  # model name -> builder options
        "train": {},  # overrides of dstenv.segment.train.default_train_config()
        "device": "auto",  # "cpu", "cuda" or "auto"
        "eval_batch_size": 8,
        "examples": 3,  # example grids in the figure
    }


#: named overrides of :func:`default_benchmark_config`
PRESETS: dict[str, dict[str, Any]] = {
    # seconds: the test suite's end-to-end run
    "tiny": {
        "data": {
            "frames": 40,
            "grid": 32,
            "episode_length": 24,
            "stride": 4,
            "warmup": 4,
            "frames_per_shard": 16,
        },
        "tune": {"episodes": 2, "budget": 3},
        "models": ["unet-light"],
        "model_kwargs": {"unet-light": {"base": 8, "depth": 2}},
        "train": {"epochs": 1, "batch_size": 4},
        "device": "cpu",
        "examples": 1,
    },
    # about a minute on 2 cores: CI's proof that every stage of the main job runs in a
    # fresh venv (generate, tune, train one short epoch, score, report)
    "smoke": {
        "data": {
            "scenario": "dense",
            "frames": 60,
            "grid": 48,
            "episode_length": 40,
            "stride": 5,
            "warmup": 5,
            "frames_per_shard": 32,
        },
        "tune": {"episodes": 2, "budget": 4},
        "models": ["unet-light"],
        "model_kwargs": {"unet-light": {"base": 8, "depth": 2}},
        "train": {"epochs": 1, "batch_size": 4},
        "device": "cpu",
        "examples": 1,
    },
    # <= 30 min on a 2-core CPU: the README's main job
    "cpu": {
        "data": {
            "scenario": "dense",
            "frames": 2000,
            "grid": 128,
            "episode_length": 200,
            "stride": 10,
            "warmup": 10,
        },
        "tune": {"episodes": 8, "budget": 30},
        "models": ["unet-light"],
        # weight_power 0.5: full median-frequency weights (x58 for moving) over-predict the
        # rare classes (moving recall 0.92, precision 0.53 in a trial run), which costs IoU
        "train": {
            "epochs": 10,
            "batch_size": 8,
            "lr": 2e-3,
            "crop": 96,
            "loss": "wce+lovasz",
            "weight_power": 0.5,
        },
        "device": "cpu",
    },
    # the full benchmark for a GPU: the paper's FCN-8s, more data, full-size grids
    "gpu": {
        "data": {
            "scenario": "dense",
            "frames": 20000,
            "grid": 256,
            "episode_length": 200,
            "stride": 10,
            "warmup": 10,
            "workers": 8,
        },
        "tune": {"episodes": 32, "budget": 60},
        "models": ["fcn8s-vgg16", "unet-light", "unet-temporal"],
        "model_kwargs": {"fcn8s-vgg16": {"dropout": 0.5}},
        "train": {
            "epochs": 30,
            "batch_size": 16,
            "lr": 1e-4,
            "loss": "wce+lovasz",
            "num_workers": 4,
        },
        "device": "auto",
    },
}


def preset_config(name: str, overrides: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The full configuration of a preset, with optional further overrides."""
    if name not in PRESETS:
        raise ConfigError(f"unknown benchmark preset {name!r}; choose from {', '.join(PRESETS)}")
    cfg = merge_config(default_benchmark_config(), PRESETS[name], f"preset {name}")
    return merge_config(cfg, overrides, "benchmark")


def _generate(dcfg: dict[str, Any], out: Path, progress: bool) -> None:
    from dstenv.data.generate import GenerateSpec, generate
    from dstenv.data.sampling import scenario_config

    g = int(dcfg["grid"])
    overrides = {"grid": {"height": g, "width": g}} if g else None
    spec = GenerateSpec(
        config=scenario_config(dcfg["scenario"] or None, overrides),
        frames=int(dcfg["frames"]),
        seed=int(dcfg["seed"]),
        scenario=dcfg["scenario"] or "default",
        split="auto",
        frames_per_shard=int(dcfg["frames_per_shard"]),
        episode_length=int(dcfg["episode_length"]),
        stride=int(dcfg["stride"]),
        warmup=int(dcfg["warmup"]),
    )
    generate(spec, out, workers=int(dcfg["workers"]), progress=progress)


def _score_dst(
    seg: Any, episodes: list[Episode]
) -> tuple[ConfusionMeter, dict[tuple[int, int], np.ndarray]]:
    meter = ConfusionMeter(len(CLASSES))
    preds = {}
    for ep in episodes:
        pred = seg.predict(torch.from_numpy(filter_episode(ep, seg.params)))
        meter.update(
            pred, torch.from_numpy(ep.labels.astype(np.int64)), torch.from_numpy(ep.visible)
        )
        for k, s in enumerate(ep.steps):
            preds[(ep.seed, int(s))] = pred[k].numpy()
    return meter, preds


def _goal(segs: dict[str, Any], kinds: dict[str, str]) -> dict[str, Any] | None:
    def best(kind: str) -> str | None:
        cands = [k for k in segs if kinds[k] == kind and segs[k]["all"]["miou"] is not None]
        return max(cands, key=lambda k: segs[k]["all"]["miou"]) if cands else None

    bl, bd = best("learned"), best("dst")
    if bl is None or bd is None:
        return None
    m = segs[bl]["all"]
    margin = m["miou"] - segs[bd]["all"]["miou"]
    mov, sta = m["iou"]["moving"], m["iou"]["static"]
    return {
        "best_learned": bl,
        "best_learned_miou": m["miou"],
        "best_dst": bd,
        "best_dst_miou": segs[bd]["all"]["miou"],
        "margin": margin,
        "margin_met": margin >= 0.15,
        "moving_iou": mov,
        "moving_met": mov is not None and mov >= 0.6,
        "static_iou": sta,
        "static_met": sta is not None and sta >= 0.5,
    }


def run_benchmark(
    config: Mapping[str, Any],
    out: str | Path,
    data_dir: str | Path | None = None,
    progress: bool = True,
    log: Callable[[str], None] = print,
    preset: str = "custom",
    command: str | None = None,
    checkpoints: Sequence[str | Path] = (),
) -> dict[str, Any]:
    """Run the whole benchmark and write its report into ``out``.

    Args:
        config: overrides of :func:`default_benchmark_config` (e.g. :func:`preset_config`).
        out: output directory (data, checkpoints, ``results.json``/``.md``, figures).
        data_dir: use existing shards instead of generating ``out/data``.
        progress: tqdm bars.
        log: receives one-line messages.
        preset: name recorded in the report.
        command: command line recorded in the report.
        checkpoints: trained networks (``dstenv train``) scored besides ``models``; on
            evaluation-only data (module docstring) the only learned segmenters.

    Returns:
        The JSON-compatible results (also in ``out/results.json``).
    """
    from dstenv.data import ShardDataset

    cfg = merge_config(default_benchmark_config(), dict(config), "benchmark")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    device = resolve_device(cfg["device"])
    timings: dict[str, float] = {}
    t = time.perf_counter()
    if data_dir is None:
        data_dir = out / "data"
        log(f"generating {cfg['data']['frames']} frames into {data_dir}")
        _generate(cfg["data"], data_dir, progress)
    data_dir = Path(data_dir)
    timings["data_s"] = time.perf_counter() - t

    test_ds = ShardDataset(data_dir, split="test", inputs="fcn10")
    if len(test_ds) == 0:
        raise ValueError(f"{data_dir}: no test frames (no shard of split 'test')")
    train_ds = ShardDataset(data_dir, split="train", inputs="fcn10")
    val_ds = ShardDataset(data_dir, split="val", inputs="fcn10")
    source = shard_attrs(test_ds.files).get("source", "sim")
    if len(train_ds) == 0 or source == "kitti":
        from dstenv.segment.stored import evaluate_stored

        results, frames, preds = evaluate_stored(
            cfg, test_ds, checkpoints, device, progress, log, source
        )
        results = {"preset": preset, "command": command, **results}
        results["data"]["dir"] = str(data_dir)
        results["timings_s"] = {**timings, **results["timings_s"]}
        segs = results["segmenters"]
        results["goal"] = _goal(segs, {k: v["kind"] for k, v in segs.items()})
        report.write_report(results, out, frames, None, preds, cfg["examples"])
        return results
    extra = load_checkpoints(checkpoints, device=device, taken=cfg["models"])  # fail early
    test_frames, gen_config = split_index(test_ds.files)
    train_frames, train_config = split_index(train_ds.files)
    if train_config != gen_config:
        raise ValueError(
            f"{data_dir}: train and test shards were generated with different configurations"
        )
    gen_params = DSTParams.from_dict(gen_config["dst"])
    segs: dict[str, Any] = {}
    kinds: dict[str, str] = {}
    described: dict[str, Any] = {}
    preds: dict[str, dict[tuple[int, int], np.ndarray]] = {}

    # DST: replay the test episodes once, check, then one filter run per parameter set
    t = time.perf_counter()
    test_eps = record_episodes(gen_config, episode_targets(test_frames), progress)
    for ep in test_eps[:2]:
        check_replay(ep, *stored_inputs(test_frames, ep.seed, ep.steps), gen_params)
    dst_segs = [create_segmenter("dst", preset=p) for p in cfg["dst_presets"]]
    timings["replay_test_s"] = time.perf_counter() - t
    if cfg["tune"]["params"]:
        dst_segs.append(create_segmenter("dst-tuned", params=cfg["tune"]["params"]))
    elif cfg["tune"]["enabled"]:
        t = time.perf_counter()
        train_eps = record_episodes(
            gen_config, episode_targets(train_frames, cfg["tune"]["episodes"]), progress
        )
        dst_segs.append(
            create_segmenter(
                "dst-tuned",
                episodes=train_eps,
                budget=cfg["tune"]["budget"],
                seed=cfg["tune"]["seed"],
                progress=progress,
            )
        )
        timings["tune_s"] = time.perf_counter() - t
        log(
            f"dst-tuned: train mIoU {dst_segs[-1].info['tuning']['start_miou']:.3f} (default) -> "
            f"{dst_segs[-1].info['tuning']['best_miou']:.3f}"
        )
    t = time.perf_counter()
    for seg in dst_segs:
        meter, preds[seg.label] = _score_dst(seg, test_eps)
        segs[seg.label], kinds[seg.label], described[seg.label] = (
            meter.summary(CLASSES),
            "dst",
            seg.describe(),
        )
    timings["dst_eval_s"] = time.perf_counter() - t

    # learned models: train on train, select on val, score on the stored test frames
    histories, learned = {}, []
    for name in cfg["models"]:
        t = time.perf_counter()
        tcfg = dict(cfg["train"])
        tcfg.update(model=name, model_kwargs=cfg["model_kwargs"].get(name, {}), device=str(device))
        mdir = out / "models" / name
        _, histories[name] = train(
            tcfg, train_ds, val_ds if len(val_ds) else None, mdir, progress=progress, log=log
        )
        timings[f"train_{name}_s"] = time.perf_counter() - t
        learned.append(load_segmenter(mdir / "best.pt", device))
    for seg in learned + extra:
        meter = evaluate(seg, batches(test_ds, cfg["eval_batch_size"]), progress=progress)
        segs[seg.label], kinds[seg.label], described[seg.label] = (
            meter.summary(CLASSES),
            "learned",
            {**seg.describe(), **({"checkpoint": seg.checkpoint} if seg in extra else {})},
        )
        preds[seg.label] = {}
        for k in sorted(report.example_ids(test_frames, cfg["examples"])):  # for the example figure
            fr = test_frames[k]
            x = torch.as_tensor(test_ds[k]["x"])[None]
            preds[seg.label][(fr["seed"], fr["step"])] = seg.predict(x)[0].numpy()

    results = {
        "preset": preset,
        "command": command,
        "config": cfg,
        "data": {
            "dir": str(data_dir),
            "train_frames": len(train_frames),
            "val_frames": len(val_ds),
            "test_frames": len(test_frames),
            "test_episodes": len(test_eps),
            "train_episodes": len({f["seed"] for f in train_frames}),
            "grid_shape": list(test_eps[0].sensor.shape[1:]),
            "cell_size": test_eps[0].cell_size,
            "generation_dst_params": gen_params.to_dict(),
        },
        "segmenters": {
            k: {**v, "kind": kinds[k], "describe": described[k]} for k, v in segs.items()
        },
        "histories": histories,
        "timings_s": timings,
    }
    results["goal"] = _goal(segs, kinds)
    report.write_report(results, out, test_frames, test_eps, preds, cfg["examples"])
    return results
