"""The goal rows of ``dstenv bench data`` (issue "a million labelled frames an hour").

Each row is the median of ``repeat`` runs (>= 3 unless ``--quick``), measured in
this process (generation rows use ``workers`` worker processes):

* generation at stride 10 with 10 Hz fusion, 2-D LIDAR (``dstenv generate``, episodes
  of 200 steps, a fresh map each, shards of generate's default size): the steady rate
  of a long run (the extra frames of a run three times as long over the extra time, so
  worker start-up cancels), with the rate of the short run, start-up included, as a
  note;
* the paper's protocol (1 Hz fusion: ``protocol.update_every = 10``) with the 2-D
  and the 3-D LIDAR, when this build has them (else the row says so);
* the same three with each map driven for :data:`MAP_REUSE` episodes
  (``--episodes-per-map``), not with ``--quick``;
* a reset of ``DSTGrid-v0`` with a fresh map;
* the write path per 256 x 256 frame on one core: labels (label grid and visible
  mask) + :class:`~dstenv.data.ShardWriter` (quantisation, compression, checksums,
  HDF5 writes), CPU time of this thread and wall time;
* ``DSTGrid-v0`` steps/s with random actions, resets included, against highway-env
  ``intersection`` with an ``OccupancyGrid`` (presence, vx, vy) of the same extent;
* one DST update at 256 x 256 on one core.
"""

from __future__ import annotations

import math
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["goal_rows", "print_goals", "timed_generate", "cpu_seconds", "MAP_REUSE"]

#: episodes per map of the goal table's map-reuse rows (``--episodes-per-map``)
MAP_REUSE = 10


def _median(fn: Callable[[], float], repeat: int) -> tuple[float, list[float]]:
    runs = [fn() for _ in range(repeat)]
    return statistics.median(runs), runs


def cpu_seconds() -> float:
    """CPU time of this process and its finished children (the pool's workers) [s].

    On a shared machine the wall-clock rate of K workers depends on what else runs;
    frames per CPU-second times the free cores is the rate of an idle machine.
    """
    import resource

    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def timed_generate(config: dict[str, Any], frames: int, workers: int, out: Path, *,
                   stride: int = 10, **spec_kw: Any) -> tuple[float, float]:
    """One ``dstenv generate`` run as every data benchmark times it.

    ``frames`` frames of seed 1 into split ``train``, episodes of 200 steps, one frame
    every ``stride`` steps from step ``stride``, shards of generate's default size
    (:class:`~dstenv.data.generate.GenerateSpec`); ``spec_kw``: other ``GenerateSpec``
    fields.

    (Before 2026-12-07 the shards held ``frames // (2 workers)`` frames: 20 in the goal
    rows, so every shard paid a fresh map for one frame of a second episode.)

    Returns:
        ``(wall [s], CPU [s])``; CPU of this process and its finished workers
        (:func:`cpu_seconds`).
    """
    from dstenv.data.generate import GenerateSpec, generate

    spec = GenerateSpec(config=config, frames=frames, seed=1, split="train", episode_length=200,
                        stride=stride, warmup=stride, **spec_kw)
    c0, t0 = cpu_seconds(), time.perf_counter()
    generate(spec, out, workers=workers, progress=False)
    return time.perf_counter() - t0, cpu_seconds() - c0


def _generate_seconds(config: dict[str, Any], frames: int, workers: int, tmp: Path,
                      **spec_kw: Any) -> float:
    out = tmp / f"gen-{len(list(tmp.iterdir()))}"
    return timed_generate(config, frames, workers, out, **spec_kw)[0]


def _generate_rates(config: dict[str, Any], frames: int, workers: int, tmp: Path,
                    **spec_kw: Any) -> dict[str, float]:
    """frames/h of a short run of ``frames`` (worker start-up included) and the steady
    rate of a long run: the extra ``2 * frames`` of a run three times as long, over the
    extra time (start-up, imports and numba cache loads cancel). NaN when the long run
    was not slower (too few frames for the noise, e.g. ``--quick``)."""
    short = _generate_seconds(config, frames, workers, tmp, **spec_kw)
    long = _generate_seconds(config, 3 * frames, workers, tmp, **spec_kw)
    return {"short_run": 3600 * frames / short,
            "steady": 3600 * 2 * frames / (long - short) if long > short else float("nan"),
            "short_s": short, "long_s": long}


def _protocol(config: dict[str, Any], three_d: bool) -> dict[str, Any] | None:
    """The paper-protocol config, or None if this build lacks the option."""
    from dstenv.config import ConfigError
    from dstenv.data.sampling import scenario_config

    over: dict[str, Any] = {"protocol": {"update_every": 10}}
    if three_d:
        over["lidar"] = {"model": "hdl64"}
    try:
        return scenario_config(config, over)
    except ConfigError:
        return None


def _write_path_ms(config: dict[str, Any], n: int, tmp: Path) -> dict[str, float]:
    """Labels + ShardWriter per frame [ms]: CPU time of this thread, and wall time.

    The writer's CPU time is then split by running its stages again on the same
    frames: quantisation (both BetP fields), deflate + Fletcher-32 of the six grid
    chunks (:func:`~dstenv.data.codec.encode_chunk`, the writer's settings), and the
    rest (HDF5 calls, label histogram, checks, file open and commit).
    """
    from dstenv.data.codec import encode_chunk, quantize_cells
    from dstenv.data.format import FORMAT_VERSION, PROB_FIELDS, QUANT_SCALE, grid_fields
    from dstenv.data.generate import GenerateSpec
    from dstenv.data.shards import ShardWriter
    from dstenv.pipeline import Pipeline
    from dstenv.sensing.labels import label_grid, visible_mask

    p = Pipeline(config)
    p.reset(7)
    frames, label_cpu, label_wall = [], 0.0, 0.0
    for k in range(10 * n + 10):
        f = p.step()
        if k >= 10 and k % 10 == 0:  # stride 10, after the warm-up
            w = p.world
            agents = w.agents  # the pipeline builds them once a step, for the sweep too
            c0, t0 = time.thread_time(), time.perf_counter()
            label_grid(w.map, agents, f.ego_pose, p.spec,
                       config["labels"]["moving_threshold"])
            visible_mask(f.sensor)
            label_cpu += time.thread_time() - c0
            label_wall += time.perf_counter() - t0
            frames.append(f)
    attrs = {"config": config, "seed": 7}
    spec = GenerateSpec(config=config, frames=n)  # the storage settings generation uses
    codec = (spec.compression, spec.compression_level, spec.deflate)
    kw = {"compression": codec[0], "compression_opts": codec[1], "deflate": codec[2]}
    with ShardWriter(tmp / "warm.h5", attrs, **kw) as wr:  # numba compilation, imports
        for f in frames[:2]:
            wr.add(f)
    # steady state: the adds (quantise, compress, checksum, buffered HDF5 writes), plus
    # opening and committing a shard (attrs, fsync, rename) spread over the default
    # 256 frames per shard
    wr = ShardWriter(tmp / "w.h5", attrs, **kw)
    c0, t0 = time.thread_time(), time.perf_counter()
    wr.__enter__()
    c1, t1 = time.thread_time(), time.perf_counter()
    for f in frames:
        wr.add(f)
    c2, t2 = time.thread_time(), time.perf_counter()
    wr.__exit__(None, None, None)
    c3, t3 = time.thread_time(), time.perf_counter()
    n = len(frames)
    write_cpu = (c2 - c1) / n + ((c1 - c0) + (c3 - c2)) / 256
    write_wall = (t2 - t1) / n + ((t1 - t0) + (t3 - t2)) / 256
    quant_cpu = deflate_cpu = 0.0
    bufs = [np.empty((*frames[0].shape, 5), np.uint8) for _ in PROB_FIELDS]  # as the writer
    for f in frames:
        c0 = time.thread_time()
        probs = [quantize_cells(getattr(f, name), QUANT_SCALE, buf)
                 for name, buf in zip(PROB_FIELDS, bufs)]
        c1 = time.thread_time()
        grids = grid_fields(FORMAT_VERSION).items()  # those the writer stores
        for a in (*probs, *(np.asarray(getattr(f, g), dt) for g, dt in grids)):
            encode_chunk(a, *codec)
        deflate_cpu += time.thread_time() - c1
        quant_cpu += c1 - c0
    return {"cpu_ms": 1e3 * (label_cpu / n + write_cpu),
            "wall_ms": 1e3 * (label_wall / n + write_wall),
            "labels_cpu_ms": 1e3 * label_cpu / n,
            "writer_cpu_ms": 1e3 * write_cpu,
            "quantise_cpu_ms": 1e3 * quant_cpu / n,
            "deflate_checksum_cpu_ms": 1e3 * deflate_cpu / n,
            "bytes_per_frame": (tmp / "w.h5").stat().st_size / n}


def _reset_ms() -> float:
    import gymnasium as gym

    import dstenv  # noqa: F401  (registers the ids)

    env = gym.make("DSTGrid-v0")
    env.reset(seed=0)  # compilation out of the timing
    times = []
    for seed in range(1, 4):  # a fresh map each: new episode seed
        t0 = time.perf_counter()
        env.reset(seed=seed)
        times.append(time.perf_counter() - t0)
    env.close()
    return 1e3 * statistics.median(times)


def _env_ratio(steps: int) -> dict[str, float]:
    import gymnasium as gym

    import dstenv  # noqa: F401
    from dstenv.envs.bench import highway_reference, time_env

    env_id, ref = highway_reference((256, 256), 0.33, "presence,vx,vy")
    ref_sps = time_env(ref, max(steps // 5, 10), resets=True)
    ref.close()
    env = gym.make("DSTGrid-v0")
    sps = time_env(env, steps, resets=True)
    env.close()
    return {"steps_per_s": sps, "highway_steps_per_s": ref_sps, "ratio": sps / ref_sps}


def _dst_ms() -> float:
    from dstenv.bench import median_ms
    from dstenv.dst import PerceptionGridFilter
    from dstenv.dst.bench import street_inputs

    sensor, gis = street_inputs(256)
    f = PerceptionGridFilter((256, 256))
    return median_ms(lambda: f.update(sensor, gis, (0.33, 0.02, 0.004), copy=False), 50, 3)


def _generation_row(runs: list[dict[str, Any]], frames: int, workers: int, goal: str
                    ) -> dict[str, Any]:
    """A generation goal row from :func:`_generate_rates` runs: the median steady rate
    over the runs that have one (``None`` and a note saying why when none has)."""
    steady = [r["steady"] for r in runs if math.isfinite(r["steady"])]
    runs = [{**r, "steady": r["steady"] if math.isfinite(r["steady"]) else None}
            for r in runs]  # JSON has no NaN
    note = ("steady rate of a long run" if len(steady) == len(runs) else
            f"steady rate of a long run (median of the {len(steady)} of {len(runs)} runs "
            "whose extra frames took measurable extra time)" if steady else
            "no steady rate: in no run did the long run's extra frames take measurable "
            "extra time (too few frames for this machine's noise; run without --quick)")
    return {"value": statistics.median(steady) if steady else None, "runs": runs,
            "unit": f"frames/h, {workers} workers", "goal": goal,
            "note": f"{note}; a run of {frames} frames with start-up: "
                    f"{statistics.median(r['short_run'] for r in runs):,.0f}"}


def goal_rows(config: dict[str, Any], repeat: int, quick: bool, workers: int = 2
              ) -> dict[str, Any]:
    """Measure every goal row; ``{row: {"value", "runs", "unit", "goal"}}``."""
    rows: dict[str, Any] = {}
    frames = 8 if quick else 256  # per worker: one shard of the default size each
    with tempfile.TemporaryDirectory(prefix="dstenv-goals-") as name:
        tmp = Path(name)
        gen = [("stride 10, 10 Hz fusion, 2-D LIDAR", config, ">= 500,000"),
               ("stride 10, paper protocol, 2-D LIDAR", _protocol(config, False), ">= 1,500,000"),
               ("stride 10, paper protocol, 3-D LIDAR", _protocol(config, True), ">= 500,000")]
        for eps in (1,) if quick else (1, MAP_REUSE):
            for label, cfg, goal in gen:
                if eps > 1:
                    label = f"{label}, {eps} episodes per map"
                if cfg is None:
                    rows[label] = {"value": None, "unit": "frames/h", "goal": goal, "note":
                                   "not in this build (protocol.update_every / lidar.model)"}
                    continue
                runs = [_generate_rates(cfg, frames * workers, workers, tmp,
                                        episodes_per_map=eps) for _ in range(repeat)]
                rows[label] = _generation_row(runs, frames * workers, workers, goal)
        value, runs = _median(_reset_ms, repeat)
        rows["reset of DSTGrid-v0 with a fresh map"] = {"value": value, "runs": runs,
                                                         "unit": "ms", "goal": "<= 150"}
        wp = [_write_path_ms(config, 12 if quick else 32, tmp) for _ in range(repeat)]
        rows["write path per frame (one core)"] = {
            "value": statistics.median(w["cpu_ms"] for w in wp), "runs": wp,
            "unit": "ms CPU", "goal": "<= 1"}
    env = [_env_ratio(30 if quick else 200) for _ in range(repeat)]
    rows["DSTGrid-v0 steps/s vs highway-env (presence, vx, vy)"] = {
        "value": statistics.median(e["ratio"] for e in env), "runs": env, "unit": "x",
        "goal": ">= 10"}
    value, runs = _median(_dst_ms, repeat)
    rows["DST update 256 x 256, one core"] = {"value": value, "runs": runs, "unit": "ms",
                                             "goal": "<= 0.6"}
    return rows


def print_goals(rows: dict[str, Any], repeat: int) -> None:
    print(f"goal rows (median of {repeat})")
    print(f"{'setting':<54}{'measured':>14}  {'unit':<22}{'goal':>12}")
    for label, r in rows.items():
        v = r["value"]
        shown = "n/a" if v is None else (f"{v:,.0f}" if v >= 1000 else f"{v:.2f}")
        print(f"{label:<54}{shown:>14}  {r['unit']:<22}{r['goal']:>12}")
        if "note" in r:
            print(f"    {r['note']}")
    wp = rows.get("write path per frame (one core)")
    if wp:
        w = wp["runs"][0]
        rest = w["writer_cpu_ms"] - w["quantise_cpu_ms"] - w["deflate_checksum_cpu_ms"]
        print(f"write path split (first run): labels {w['labels_cpu_ms']:.2f} ms + writer "
              f"{w['writer_cpu_ms']:.2f} ms CPU (quantise {w['quantise_cpu_ms']:.2f}, deflate "
              f"+ checksum {w['deflate_checksum_cpu_ms']:.2f}, HDF5 and the rest {rest:.2f}); "
              f"wall {w['wall_ms']:.2f} ms; {w['bytes_per_frame']:,.0f} B/frame")
