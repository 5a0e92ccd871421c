"""The benchmark's configuration: every option with its default, the presets, the
paper's protocol and the checks that run before any work (``dstenv benchmark``,
:mod:`dstenv.segment.benchmark`).
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any

from dstenv.config import ConfigError, merge_config

__all__ = [
    "PRESETS",
    "REAL_NET_MAPS",
    "REAL_NET_MOVING",
    "REAL_NET_INPUTS",
    "PAPER_PROTOCOL",
    "check_config",
    "default_benchmark_config",
    "preset_config",
    "protocol_overrides",
]


#: ``real_net.map`` values (:func:`dstenv.segment.realnet.train_real_networks`)
REAL_NET_MAPS = ("match", "run")
#: ``real_net.inputs`` values (:data:`dstenv.data.datasets.INPUTS` that read the sensor)
REAL_NET_INPUTS = ("fcn10+sensor", "fcn10+sensor+past")
#: ``real_net.moving`` values (:func:`dstenv.segment.realnet.train_real_networks`)
REAL_NET_MOVING = ("match", "run")


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
        "dst_free": True,  # add `dst-free`: DST, no obstacle on cells the sweep saw free
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
        "real_net": {
            # with --kitti: networks for the real drives, trained on simulated drives at
            # the converted data's grid with KITTI's label convention and the sensor grid
            # as input (dstenv.segment.realnet); rows "MODEL kitti-labels"; 0 frames = off
            "frames": 0,
            "epochs": 5,
            "seeds": [0],
            "model": "unet-light",
            # "match": drives without a map when the real drives have none (converted
            # without --osm), else the run's map settings; "run": always the run's
            "map": "match",
            # the networks' input (dstenv.data.datasets): "fcn10+sensor", or with the
            # sensor grid of one second earlier too, "fcn10+sensor+past" (the default
            # since 2026-12-06: with moving "match", simulated validation drives read it
            # better, six seeds each; docs/benchmark.md)
            "inputs": "fcn10+sensor+past",
            # which agents the drives label moving: "match", the real labels' rule (KITTI's:
            # faster than 10 cm a 0.1 s frame, 1 m/s); "run", the simulated run's
            # (labels.moving_threshold, 0.1 m/s)
            "moving": "match",
            # also score each network with the decision rule chosen on its simulated
            # validation drives (dstenv.segment.decide: a static/moving offset and the
            # free-space rule), rows "... calibrated + free" (docs/benchmark.md)
            "decide": True,
            # with decide and two or more seeds, also score the seeds' ensemble (the mean of
            # their logits) with a decision chosen the same way on its own scores, row
            # "... ensemble of N seeds, calibrated + free" (docs/preregistration-ensemble.md)
            "ensemble": True,
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
    # the README's main job, aimed at <= 30 min on a 2-core CPU (measured 21.6 min on the
    # idle machine, docs/benchmark.md). Short episodes on many maps:
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
            "flip": 0.0,  # no mirroring (docs/benchmark.md: tried for real_net)
            "loss": "wce+lovasz",
            "weight_power": 0.5,  # chosen on validation: benchmarks/search/cpu-weight-power.json
        },
        # the no-map network for KITTI without OSM: +2 epochs on the ~500 map-free frames
        "no_map": {"epochs": 2},
        # with --kitti: three networks on 600 simulated frames at the converted grid
        # (KITTI's 256 x 256), KITTI's labels, the sensor grid as input, no map when
        # the real drives have none (real_net.map = "match")
        "real_net": {"frames": 600, "epochs": 5, "seeds": [0, 1, 2]},
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
        "real_net": {"frames": 4000, "epochs": 10, "seeds": [0, 1, 2]},
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
    if overrides is None:
        return cfg
    if not isinstance(overrides, Mapping):
        raise ConfigError("benchmark: expected a table of settings, got "
                          f"{type(overrides).__name__}")
    # merged into the preset first, then checked against the defaults once: a table
    # that is free-form there (data.overrides, model_kwargs) stays free-form, whatever
    # keys the preset itself set in it
    return merge_config(default_benchmark_config(), _layered(PRESETS[name], overrides),
                        "benchmark")


def _layered(base: Mapping[str, Any], over: Mapping[str, Any]) -> dict[str, Any]:
    """``over`` on top of ``base``: tables merge key by key, other values replace."""
    out = dict(base)
    for k, v in over.items():
        out[k] = (_layered(out[k], v) if isinstance(v, Mapping) and isinstance(out.get(k), Mapping)
                  else v)
    return out


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


def check_config(cfg: Mapping[str, Any]) -> None:
    """Raise :class:`~dstenv.config.ConfigError` on a benchmark option that cannot work
    (named, with the fix), before any stage runs."""
    seeds = cfg["train_seeds"]
    if not seeds or len(set(seeds)) != len(seeds):
        raise ConfigError(f"train_seeds: need distinct seeds, got {seeds}")
    d = cfg["data"]
    for key, low in (("frames", 1), ("episode_length", 1), ("stride", 1), ("warmup", 0),
                     ("workers", 1), ("frames_per_shard", 1), ("episodes_per_map", 1),
                     ("grid", 0)):
        if not isinstance(d[key], int) or isinstance(d[key], bool) or d[key] < low:
            raise ConfigError(f"data.{key} must be an integer >= {low}, got {d[key]!r}")
    from dstenv.config import build_config

    build_config(d["scenario"] or None, ("data.overrides", d["overrides"]))  # names a bad key
    if not isinstance(cfg["eval_batch_size"], int) or cfg["eval_batch_size"] < 1:
        raise ConfigError(f"eval_batch_size must be an integer >= 1, got "
                          f"{cfg['eval_batch_size']!r}")
    from dstenv.segment.train import check_train_config, default_train_config

    check_train_config(cfg["train"])  # not after the data is generated and scored
    if cfg["search"]["values"] and cfg["search"]["key"] not in default_train_config():
        raise ConfigError(
            f"search.key: {cfg['search']['key']!r} is not a training option; choose from "
            + ", ".join(default_train_config())
        )
    nm = cfg["no_map"]
    if not (isinstance(nm["epochs"], int) and nm["epochs"] >= 0) or not float(nm["lr"]) > 0:
        raise ConfigError(f"no_map: epochs must be an integer >= 0 and lr > 0, got {dict(nm)}")
    rn = cfg["real_net"]
    if not (isinstance(rn["frames"], int) and rn["frames"] >= 0 and isinstance(rn["epochs"], int)
            and rn["epochs"] >= 1) or not rn["seeds"] or len(set(rn["seeds"])) != len(rn["seeds"]):
        raise ConfigError(f"real_net: frames must be an integer >= 0, epochs >= 1 and seeds "
                          f"distinct, got {dict(rn)}")
    from dstenv.segment.models import MODELS

    if rn["map"] not in REAL_NET_MAPS:
        raise ConfigError(f"real_net.map: unknown {rn['map']!r}; choose from "
                          + ", ".join(REAL_NET_MAPS))
    if rn["moving"] not in REAL_NET_MOVING:
        raise ConfigError(f"real_net.moving: unknown {rn['moving']!r}; choose from "
                          + ", ".join(REAL_NET_MOVING))
    if rn["inputs"] not in REAL_NET_INPUTS:
        raise ConfigError(f"real_net.inputs: unknown {rn['inputs']!r}; choose from "
                          + ", ".join(REAL_NET_INPUTS))
    for key in ("decide", "ensemble"):
        if not isinstance(rn[key], bool):
            raise ConfigError(f"real_net.{key}: true or false, got {rn[key]!r}")
    if rn["model"] not in MODELS:
        raise ConfigError(f"real_net.model: unknown model {rn['model']!r}; choose from "
                          + ", ".join(MODELS))
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
