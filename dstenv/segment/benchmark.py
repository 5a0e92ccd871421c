"""``dstenv benchmark``: DST, non-learned baselines and networks on held-out drives.

Stages (each resumable: rerunning the same command reuses finished work):

1. **data** -- ``dstenv.data.generate`` writes train/val/test shards whose splits
   come from disjoint map seeds (:mod:`dstenv.data.sampling`), so the test maps
   are never seen in training, tuning or model selection.
2. **drives** -- the test episodes are replayed (:mod:`dstenv.segment.replay`)
   and checked against the stored BetP; frames are keyed by ``(seed, episode,
   step)`` so several episodes per map work.
3. **non-learned baselines, tuned on train only** -- ``dst`` for each preset of
   ``dst_presets``; ``dst-tuned`` (:mod:`dstenv.segment.tune`, the objective is
   the headline scope); ``dst-complete`` (:mod:`dstenv.segment.complete`, DST
   with the ``dst-tuned`` parameters plus a vehicle-box completion searched on
   training drives).
4. **networks** -- each model of ``models`` is trained once per seed of
   ``train_seeds`` (``best.pt`` picked on validation); ``curve.frames`` adds the
   training-set-size curve (the same model trained on the first N training frames).
5. **score** -- one call of :func:`dstenv.segment.score.score` scores every
   segmenter on the same frames, over ``observed`` (headline), ``visible`` and
   ``all`` (amodal) cells, with object-level counts, per drive.
6. **report** -- ``results.json`` (schema in ``docs/benchmark.md``),
   ``results.md`` and figures in ``out``; 95 % intervals are a cluster bootstrap
   over maps (:mod:`dstenv.segment.stats`).

**Evaluation-only data** (``source = "kitti"`` shards of ``dstenv kitti convert``,
or shards without a train split) is scored by the same :func:`score`: DST with
the generation parameters from the stored BetP, other DST parameters only when
the shards hold every filtered frame (:func:`dstenv.segment.replay.stored_episodes`),
fixed ``tune.params`` / ``complete.params``, and the given checkpoints.

``protocol = "paper"`` applies :data:`PAPER_PROTOCOL` to the generated data (1 Hz
fusion with t-1 the previous fused grid, camera field-of-view labels, KITTI's
moving rule, an imperfect map); a key the simulator does not have is a
:class:`~dstenv.config.ConfigError` naming it.
"""

from __future__ import annotations

import copy
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from dstenv.config import ConfigError, merge_config
from dstenv.dst.frame import CLASSES
from dstenv.segment import report
from dstenv.segment.results import (
    SCHEMA_VERSION,
    goal,
    real_goal,
    segmenter_results,
    tie_summary,
)

__all__ = [
    "PRESETS",
    "PAPER_PROTOCOL",
    "default_benchmark_config",
    "preset_config",
    "protocol_overrides",
    "run_benchmark",
]


#: [bytes] largest train/val split kept in memory between epochs (ShardDataset cache)
_CACHE_BYTES = 2 << 30


def default_benchmark_config() -> dict[str, Any]:
    """Every benchmark option with its default (the presets override some)."""
    return {
        "data": {
            "scenario": "",  # scenario name or .toml file; "" = default configuration
            "frames": 1000,  # total frames, split 80/10/10 train/val/test by map seed
            "seed": 0,
            "grid": 128,  # [cells] side of the square grid; 0 keeps the scenario's grid
            "episode_length": 200,  # [steps] of 0.1 s
            "stride": 10,  # keep one frame every `stride` steps
            "warmup": 10,  # [steps] first kept step
            "episodes_per_map": 1,  # episodes driven on each map (new traffic each)
            "workers": 1,  # generation processes
            "frames_per_shard": 256,
            "overrides": {},  # pipeline configuration overrides (any section)
        },
        "protocol": "sim",  # "sim" or "paper" (PAPER_PROTOCOL)
        "dst_presets": ["default", "paper"],  # DSTParams presets scored as `dst`
        "tune": {
            "enabled": True,  # add `dst-tuned`
            "episodes": 8,  # training episodes replayed for the search
            "budget": 30,  # parameter sets scored
            "seed": 0,
            "scope": "observed",  # cells of the search objective (dstenv.segment.score)
            # fixed dst-tuned parameters: DSTParams fields, or the "describe" entry of
            # a results.json row (its "params" are used); {} = search on the train split
            "params": {},
        },
        "complete": {
            "enabled": True,  # add `dst-complete`
            "scope": "all",  # objective of the box search: completion is for hidden cells
            "params": {},  # fixed completion settings (complete_frame kwargs) or a describe
        },
        "models": ["unet-light"],  # learned segmenters to train (dstenv.segment.models.MODELS)
        "model_kwargs": {},  # model name -> builder options
        "train": {},  # overrides of dstenv.segment.train.default_train_config()
        "train_seeds": [0],  # one network per seed and model; rows pool the seeds
        "no_map": {
            # each trained network fine-tuned on the training drives fused without a map
            # (gis.no_map_prob), for users without one (KITTI without OSM): rows
            # "NAME no-map"; 0 epochs = off
            "epochs": 0,
            "lr": 5e-4,  # Adam learning rate of the fine-tuning
        },
        "curve": {
            "frames": [],  # training-set sizes, e.g. [140, 1400, 14000]
            "model": "unet-light",
        },
        "search": {
            # one training option chosen on validation drives (headline scope) before the
            # main training, e.g. key "weight_power", values [0.25, 0.5, 1.0]; [] = off
            "key": "weight_power",
            "values": [],
        },
        "bootstrap": {"resamples": 1000, "seed": 0},
        # score only frames whose step is >= this (earlier ones may serve fine-tuning;
        # the filter and the observed cells still use every earlier sweep)
        "score_from_step": 0,
        "device": "auto",  # "cpu", "cuda" or "auto"
        "eval_batch_size": 8,
        "examples": 3,  # example grids in the figure
    }


#: pipeline configuration of the paper's protocol (the ``protocol`` section of issue 13);
#: the map is imperfect by default since issue 12 (``gis`` errors of the scenario)
PAPER_PROTOCOL: dict[str, Any] = {
    "protocol": {
        "update_every": 10,  # [steps] fuse at 1 Hz; t-1 = the previous fused grid
        "camera_fov": 81.0,  # [deg] labels only in KITTI's left colour camera's view
        "moving_rule": "displacement",  # KITTI's rule: moved > 10 cm frame to frame
    },
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
        "complete": {"params": {"length_m": 4.5, "width_m": 1.8}},
        "models": ["unet-light"],
        "model_kwargs": {"unet-light": {"base": 8, "depth": 2}},
        "train": {"epochs": 1, "batch_size": 4},
        "bootstrap": {"resamples": 200},
        "device": "cpu",
        "examples": 1,
    },
    # about a minute on 2 cores: CI's proof that every stage of the main job runs in a
    # fresh venv (generate, tune, complete, train one short epoch, score, report)
    "smoke": {
        "data": {
            "scenario": "dense",
            "frames": 60,
            "grid": 48,
            "episode_length": 40,
            "stride": 5,
            "warmup": 5,
            "frames_per_shard": 32,
            "overrides": {"gis": {"no_map_prob": 0.5}},
        },
        "tune": {"episodes": 2, "budget": 4},
        "complete": {"params": {"length_m": 4.5, "width_m": 1.8}},
        "models": ["unet-light"],
        "model_kwargs": {"unet-light": {"base": 8, "depth": 2}},
        "train": {"epochs": 1, "batch_size": 4},
        "no_map": {"epochs": 1},
        "bootstrap": {"resamples": 200},
        "device": "cpu",
        "examples": 1,
    },
    # the README's main job, aimed at <= 30 min on a 2-core CPU (measured 51 min on shared
    # cores, docs/benchmark.md: not yet). Short episodes on many maps:
    # 2500 frames = 500 maps of 5 frames, about 50 test maps for the bootstrap; the 3-D
    # LIDAR (the same point-cloud road as KITTI scans), a quarter of the drives without
    # a map, three training seeds of 6 epochs, each then fine-tuned on the drives without
    # a map (the network for users without an OSM file, e.g. KITTI)
    "cpu": {
        "data": {
            "scenario": "dense",
            "frames": 2500,
            "grid": 128,
            "episode_length": 60,
            "stride": 10,
            "warmup": 10,
            "workers": 2,
            "overrides": {"lidar": {"model": "hdl64"}, "gis": {"no_map_prob": 0.25}},
        },
        "tune": {"episodes": 16, "budget": 60},
        "models": ["unet-light"],
        "train_seeds": [0, 1, 2],
        "train": {
            "epochs": 6,
            "batch_size": 8,
            "lr": 2e-3,
            "crop": 96,
            "loss": "wce+lovasz",
            "weight_power": 0.5,  # not yet chosen by a recorded search (search.values runs one)
        },
        # the no-map network for KITTI without OSM: +2 epochs on the ~500 map-free frames
        "no_map": {"epochs": 2},
        "device": "cpu",
    },
    # the full benchmark for a GPU: the paper's FCN-8s, more data, full-size grids,
    # three training seeds
    "gpu": {
        "data": {
            "scenario": "dense",
            "frames": 20000,
            "grid": 256,
            "episode_length": 100,
            "stride": 10,
            "warmup": 10,
            "workers": 8,
        },
        "tune": {"episodes": 32, "budget": 120},
        "models": ["fcn8s-vgg16", "unet-light", "unet-temporal"],
        "model_kwargs": {"fcn8s-vgg16": {"dropout": 0.5}},
        "train": {
            "epochs": 30,
            "batch_size": 16,
            "lr": 1e-4,
            "loss": "wce+lovasz",
            "num_workers": 4,
        },
        "train_seeds": [0, 1, 2],
        "device": "auto",
    },
    # the training-set-size curve: the paper's 140 frames, x10, x100, each network
    # trained with the same 2000 optimiser steps (8 epochs of 250 batches drawn with
    # replacement), so only the amount of data differs; about an hour on 2 CPU cores.
    # With --protocol paper it is the paper's conditions (1 Hz fusion, camera view)
    "curve": {
        "data": {
            "scenario": "dense",
            "frames": 17600,  # 80 % train: 14080 >= the largest curve size
            "grid": 128,
            "episode_length": 200,  # 19 frames per drive: ~930 maps, ~90 test maps
            "stride": 10,
            "warmup": 10,
            "workers": 2,
        },
        "tune": {"episodes": 16, "budget": 60},
        "models": [],
        "curve": {"frames": [140, 1400, 14000], "model": "unet-light"},
        "train": {"epochs": 8, "fixed_batches": 250, "batch_size": 8, "lr": 2e-3, "crop": 96,
                  "loss": "wce+lovasz", "weight_power": 0.5},
        "device": "auto",
    },
}


def preset_config(name: str, overrides: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The full configuration of a preset, with optional further overrides."""
    if name not in PRESETS:
        raise ConfigError(f"unknown benchmark preset {name!r}; choose from {', '.join(PRESETS)}")
    cfg = merge_config(default_benchmark_config(), PRESETS[name], f"preset {name}")
    return merge_config(cfg, overrides, "benchmark")


def _missing_keys(base: Mapping[str, Any], over: Mapping[str, Any], path: str = "") -> list[str]:
    out = []
    for k, v in over.items():
        key = f"{path}{k}"
        if k not in base:
            out.append(key)
        elif isinstance(v, Mapping) and isinstance(base[k], Mapping):
            out += _missing_keys(base[k], v, f"{key}.")
    return out


def protocol_overrides(protocol: str) -> dict[str, Any]:
    """Pipeline overrides of a protocol (``"sim"``: none; ``"paper"``: :data:`PAPER_PROTOCOL`).

    Raises:
        ConfigError: an unknown protocol, or a key of :data:`PAPER_PROTOCOL` the
            pipeline configuration does not have (named, with where it comes from).
    """
    if protocol == "sim":
        return {}
    if protocol != "paper":
        raise ConfigError(f"protocol: unknown {protocol!r}; choose from sim, paper")
    from dstenv.pipeline import default_config

    missing = _missing_keys(default_config(), PAPER_PROTOCOL)
    if missing:
        raise ConfigError(
            "protocol paper needs the pipeline configuration keys "
            + ", ".join(missing)
            + " (1 Hz fusion, camera-FOV labels, KITTI moving rule of issue 13), which "
            "this dstenv does not have; update dstenv or use --protocol sim"
        )
    return copy.deepcopy(PAPER_PROTOCOL)


def _check(cfg: Mapping[str, Any]) -> None:
    seeds = cfg["train_seeds"]
    if not seeds or len(set(seeds)) != len(seeds):
        raise ConfigError(f"train_seeds: need distinct seeds, got {seeds}")
    from dstenv.segment.train import default_train_config

    if cfg["search"]["values"] and cfg["search"]["key"] not in default_train_config():
        raise ConfigError(
            f"search.key: {cfg['search']['key']!r} is not a training option; choose from "
            + ", ".join(default_train_config())
        )
    nm = cfg["no_map"]
    if not (isinstance(nm["epochs"], int) and nm["epochs"] >= 0) or not float(nm["lr"]) > 0:
        raise ConfigError(f"no_map: epochs must be an integer >= 0 and lr > 0, got {dict(nm)}")
    if any(int(n) < 1 for n in cfg["curve"]["frames"]):
        raise ConfigError(f"curve.frames: sizes must be >= 1, got {cfg['curve']['frames']}")
    from dstenv.segment.score import SCOPES

    period = PAPER_PROTOCOL["protocol"]["update_every"] if cfg["protocol"] == "paper" else 1
    for key in ("stride", "warmup"):
        if int(cfg["data"][key]) % period:
            raise ConfigError(
                f"data.{key} = {cfg['data'][key]}: the paper protocol fuses every {period} "
                f"steps and only fused frames are scored; use a multiple of {period}"
            )
    for key in ("tune", "complete"):
        if cfg[key]["scope"] not in SCOPES:
            raise ConfigError(
                f"{key}.scope: unknown {cfg[key]['scope']!r}; choose from {', '.join(SCOPES)}"
            )


def _generate(dcfg: dict[str, Any], protocol: str, out: Path, progress: bool) -> None:
    from dstenv.data.generate import GenerateSpec, generate
    from dstenv.data.sampling import scenario_config

    g = int(dcfg["grid"])
    overrides: dict[str, Any] = {"grid": {"height": g, "width": g}} if g else {}
    overrides = _deep_update(overrides, protocol_overrides(protocol))
    overrides = _deep_update(overrides, dcfg["overrides"])
    spec = GenerateSpec(
        config=scenario_config(dcfg["scenario"] or None, overrides or None),
        frames=int(dcfg["frames"]),
        seed=int(dcfg["seed"]),
        scenario=dcfg["scenario"] or "default",
        split="auto",
        frames_per_shard=int(dcfg["frames_per_shard"]),
        episode_length=int(dcfg["episode_length"]),
        stride=int(dcfg["stride"]),
        warmup=int(dcfg["warmup"]),
        episodes_per_map=int(dcfg["episodes_per_map"]),
    )
    generate(spec, out, workers=int(dcfg["workers"]), progress=progress)


def _deep_update(base: dict[str, Any], over: Mapping[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for k, v in over.items():
        out[k] = _deep_update(out.get(k, {}), v) if isinstance(v, Mapping) else v
    return out


def run_benchmark(
    config: Mapping[str, Any],
    out: str | Path,
    data_dir: str | Path | None = None,
    progress: bool = True,
    log: Callable[[str], None] = print,
    preset: str = "custom",
    command: str | None = None,
    checkpoints: Sequence[str | Path] = (),
    split: str = "test",
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
        split: the split scored (``"test"``; a KITTI conversion may use another name).

    Returns:
        The JSON-compatible results (also in ``out/results.json``).
    """
    from dstenv.data import ShardDataset
    from dstenv.segment.plan import plan_segmenters, split_drives
    from dstenv.segment.score import score
    from dstenv.segment.train import resolve_device

    cfg = merge_config(default_benchmark_config(), dict(config), "benchmark")
    _check(cfg)
    protocol_overrides(cfg["protocol"])  # fail before any work
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    device = resolve_device(cfg["device"])
    timings: dict[str, float] = {}
    t = time.perf_counter()
    if data_dir is None:
        data_dir = out / "data"
        log(f"generating {cfg['data']['frames']} frames into {data_dir}")
        _generate(cfg["data"], cfg["protocol"], data_dir, progress)
    data_dir = Path(data_dir)
    timings["data_s"] = time.perf_counter() - t

    test_ds = ShardDataset(data_dir, split=split, inputs="fcn10")
    if len(test_ds) == 0:
        raise ValueError(f"{data_dir}: no test frames (no shard of split {split!r})")
    datasets = {s: ShardDataset(data_dir, split=s, inputs="fcn10") for s in ("train", "val")}
    cells = int(test_ds[0]["labels"].numel())
    for ds in datasets.values():  # later epochs skip decompression when a split fits
        ds.cache = len(ds) * (2 * 5 + 2) * cells <= _CACHE_BYTES
    t = time.perf_counter()
    drives = split_drives(test_ds, len(datasets["train"]) == 0, progress, log,
                          int(cfg["score_from_step"]))
    timings["replay_test_s"] = time.perf_counter() - t
    plan = plan_segmenters(cfg, drives, datasets, checkpoints, device, out, progress, log,
                           timings)
    t = time.perf_counter()
    example_keys = report.example_keys(drives.episodes, cfg["examples"])
    scores = score(plan.segmenters, drives.episodes, drives.generation_params,
                   cfg["eval_batch_size"], example_keys, progress)
    timings["score_s"] = time.perf_counter() - t
    for label, why in scores.unscored.items():
        plan.unscored[label] = why
    segs, confusion, weights = segmenter_results(
        scores, plan.kinds, plan.described, plan.seed_groups,
        cfg["bootstrap"]["resamples"], cfg["bootstrap"]["seed"],
    )
    curve = {label: segs.pop(label) for label in plan.curve if label in segs}
    first = next(iter(scores.confusion.values()), None)
    shares = {} if first is None else {
        sc: dict(zip(CLASSES, (first[sc].sum((0, 2)) / max(int(first[sc].sum()), 1)).tolist()))
        for sc in first
    }
    results: dict[str, Any] = {
        "schema": SCHEMA_VERSION,
        "preset": None if drives.evaluation_only else preset,
        "command": command,
        "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "config": cfg,
        "data": {**drives.describe(), "dir": str(data_dir),
                 "train_frames": len(datasets["train"]), "val_frames": len(datasets["val"]),
                 "observed_definition": scores.observed_definition,
                 "class_shares": shares,
                 "no_map_ties": tie_summary(scores)},
        "segmenters": segs,
        "curve": [{"train_frames": plan.curve[label], "label": label, **curve[label]}
                  for label in sorted(curve, key=lambda k: plan.curve[k])],
        "search": plan.search,
        "unscored": plan.unscored,
        "histories": plan.histories,
        "timings_s": timings,
    }
    if drives.evaluation_only:
        ref = next((k for k in segs if segs[k]["kind"] == "dst"
                    and segs[k]["describe"]["params"] == drives.generation_params.to_dict()),
                   None)
        results["goal"] = None
        results["real_goal"] = (real_goal(segs, confusion, weights, ref)
                                if drives.source == "kitti" and ref else None)
    else:
        results["goal"] = goal(segs, confusion, weights)
    report.write_report(results, out, drives.episodes, drives.generation_params,
                        scores.examples)
    if plan.search:
        report.write_json(out / "search.json", {"command": command, "date": results["date"],
                                                "preset": preset, **plan.search})
    return results
