"""``dstenv benchmark``: DST, non-learned baselines and networks on held-out drives.

Stages (each resumable: rerunning the same command reuses finished work):

1. **data** -- ``dstenv.data.generate`` writes train/val/test shards whose splits
   come from disjoint map seeds (:mod:`dstenv.data.sampling`), so the test maps
   are never seen in training, tuning or model selection.
2. **drives** -- the test episodes are replayed (:mod:`dstenv.segment.replay`)
   and checked against the stored BetP; frames are keyed by ``(seed, episode,
   step)`` so several episodes per map work.
3. **non-learned baselines, tuned on train only** -- ``dst`` for each preset of
   ``dst_presets``; ``dst-free`` (``dst_free``: the generation parameters, no obstacle
   on cells the current sweep saw free); ``dst-tuned`` (:mod:`dstenv.segment.tune`, the objective is
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
the shards hold every filtered frame (:func:`dstenv.segment.shardindex.stored_episodes`),
fixed ``tune.params`` / ``complete.params``, and the given checkpoints.

``protocol = "paper"`` applies :data:`~dstenv.segment.presets.PAPER_PROTOCOL` to the
generated data (1 Hz fusion with t-1 the previous fused grid, camera field-of-view labels, KITTI's
moving rule, an imperfect map); a key the simulator does not have is a
:class:`~dstenv.config.ConfigError` naming it.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from dstenv.config import merge_config
from dstenv.dst.frame import CLASSES
from dstenv.segment import report
from dstenv.segment.presets import check_config, default_benchmark_config, protocol_overrides
from dstenv.segment.results import (
    SCHEMA_VERSION,
    goal,
    real_goal,
    segmenter_results,
    tie_summary,
)

__all__ = ["run_benchmark", "generate_data"]


#: [bytes] largest train/val split kept in memory between epochs (ShardDataset cache)
_CACHE_BYTES = 2 << 30


def generate_data(dcfg: Mapping[str, Any], protocol: str, out: Path, progress: bool,
                  cell_size: float | None = None, no_map: bool = False,
                  moving_threshold: float | None = None) -> None:
    """Generate (or resume) a benchmark's shards into ``out``.

    Args:
        dcfg: a benchmark configuration's ``data`` section.
        protocol: ``"sim"`` or ``"paper"`` (:func:`protocol_overrides`).
        out: the dataset directory.
        progress: tqdm bars.
        cell_size: [m] grid cell size, over ``dcfg["overrides"]``; ``None`` keeps the
            scenario's (or the overrides').
        no_map: every drive without a map (``gis.source = "none"``), over
            ``dcfg["overrides"]``.
        moving_threshold: [m/s] label an agent moving above this speed
            (``protocol.moving_rule = "speed"``), over ``dcfg["overrides"]``; ``None``
            keeps the configured rule.
    """
    from dstenv.data.generate import GenerateSpec, generate
    from dstenv.data.sampling import scenario_config

    g = int(dcfg["grid"])
    overrides: dict[str, Any] = {"grid": {"height": g, "width": g}} if g else {}
    overrides = _deep_update(overrides, protocol_overrides(protocol))
    overrides = _deep_update(overrides, dcfg["overrides"])
    if cell_size is not None:  # wins over data.overrides: it must match other data
        overrides = _deep_update(overrides, {"grid": {"cell_size": float(cell_size)}})
    if no_map:
        overrides = _deep_update(overrides, {"gis": {"source": "none"}})
    if moving_threshold is not None:
        overrides = _deep_update(overrides, {"protocol": {"moving_rule": "speed"},
                                             "labels": {"moving_threshold": moving_threshold}})
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


#: the data a benchmark folder's trained networks and results belong to
_DATA_RECORD = "data-identity.json"


def _same_data(out: Path, data_dir: Path) -> None:
    """Refuse to resume ``out`` on other data than it was made with (its networks would
    be scored on data they were not trained on, its results replaced in silence);
    record the data on a first run."""
    from dstenv.data.manifest import MANIFEST_NAME, data_identity, one_dataset
    from dstenv.io import atomic_write_text

    if not (data_dir / MANIFEST_NAME).is_file():
        one_dataset(data_dir)  # several datasets (or a split folder): refused before any record
    ident = {"data": str(data_dir.resolve()), "sha256": data_identity(data_dir)}
    path = out / _DATA_RECORD
    if path.exists():
        try:
            old = json.loads(path.read_text())
        except (OSError, ValueError):
            old = {}
        made = [n for n in ("results.json", "models", "curve", "search.json")
                if (out / n).exists()]
        if old.get("sha256") != ident["sha256"] and made:
            what = (f"the data in {ident['data']} changed since" if old.get("data") ==
                    ident["data"] else f"it was made on {old.get('data', '?')}")
            raise ValueError(f"{out}: holds a benchmark of other data ({what}; it has "
                             f"{', '.join(made)}); choose another --out, or remove it to "
                             "start over")
        if old.get("sha256") == ident["sha256"]:
            return
        # a run that failed before making anything: its record does not bind the folder
    atomic_write_text(path, json.dumps(ident, indent=1) + "\n")


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
    dst_rows: Sequence[Any] = (),
    finetuned: Sequence[str] = (),
) -> dict[str, Any]:
    """Run the whole benchmark and write its report into ``out``.

    Args:
        config: overrides of :func:`~dstenv.segment.presets.default_benchmark_config`
            (e.g. :func:`~dstenv.segment.presets.preset_config`).
        out: output directory (data, checkpoints, ``results.json``/``.md``, figures).
        data_dir: use existing shards instead of generating ``out/data``.
        progress: tqdm bars.
        log: receives one-line messages.
        preset: name recorded in the report.
        command: command line recorded in the report.
        checkpoints: trained networks (``dstenv train``) scored besides ``models``; on
            evaluation-only data (module docstring) the only learned segmenters.
        split: the split scored (``"test"``; a KITTI conversion may use another name).
        dst_rows: more :class:`~dstenv.segment.segmenters.DSTSegmenter` rows with fixed
            parameters (:func:`~dstenv.segment.plan.plan_segmenters`).
        finetuned: labels of the networks trained on real frames, held to the real-data
            goal's larger margin (:data:`~dstenv.segment.results.MARGIN_REAL_FINETUNED`).

    Returns:
        The JSON-compatible results (also in ``out/results.json``).
    """
    from dstenv.data import ShardDataset
    from dstenv.segment.plan import plan_segmenters, split_drives
    from dstenv.segment.score import score
    from dstenv.segment.train import resolve_device

    cfg = merge_config(default_benchmark_config(), dict(config), "benchmark")
    check_config(cfg)
    protocol_overrides(cfg["protocol"])  # fail before any work
    for ckpt in checkpoints or ():  # not after the data is generated and scored
        path = ckpt[1] if isinstance(ckpt, tuple) else ckpt  # a path, or (label, path)
        if isinstance(path, (str, Path)) and not Path(path).is_file():
            raise FileNotFoundError(f"checkpoint not found: {path}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    device = resolve_device(cfg["device"])
    timings: dict[str, float] = {}
    t = time.perf_counter()
    if data_dir is None:
        data_dir = out / "data"
        log(f"generating {cfg['data']['frames']} frames into {data_dir}")
        generate_data(cfg["data"], cfg["protocol"], data_dir, progress)
    data_dir = Path(data_dir)
    _same_data(out, data_dir)
    timings["data_s"] = time.perf_counter() - t

    test_ds = ShardDataset(data_dir, split=split, inputs="fcn10")
    if len(test_ds) == 0:
        raise ValueError(f"{data_dir}: no {split} frames (no shard of split {split!r})")
    datasets = {s: ShardDataset(data_dir, split=s, inputs="fcn10") for s in ("train", "val")}
    cells = int(test_ds[0]["labels"].numel())
    for ds in datasets.values():  # later epochs skip decompression when a split fits
        ds.cache = len(ds) * (2 * 5 + 2) * cells <= _CACHE_BYTES
    t = time.perf_counter()
    drives = split_drives(test_ds, len(datasets["train"]) == 0, progress, log,
                          int(cfg["score_from_step"]))
    timings["replay_test_s"] = time.perf_counter() - t
    plan = plan_segmenters(cfg, drives, datasets, checkpoints, device, out, progress, log,
                           timings, dst_rows)
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
        "notes": plan.notes,
        "histories": plan.histories,
        "timings_s": timings,
    }
    if drives.evaluation_only:
        ref = next((k for k in segs if segs[k]["describe"]["name"] == "dst"
                    and segs[k]["describe"]["params"] == drives.generation_params.to_dict()),
                   None)
        results["goal"] = None
        results["real_goal"] = (real_goal(segs, confusion, weights, ref, finetuned=finetuned)
                                if drives.source == "kitti" and ref else None)
    else:
        results["goal"] = goal(segs, confusion, weights)
    report.write_report(results, out, drives.episodes, drives.generation_params,
                        scores.examples)
    if plan.search:
        report.write_json(out / "search.json", {"command": command, "date": results["date"],
                                                "preset": preset, **plan.search})
    return results
