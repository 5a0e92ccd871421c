"""``dstenv generate``: labelled frames from autopilot episodes, written as shards.

The work is cut into shard tasks (:func:`plan`): shard ``k`` of split ``s`` holds
``frames_per_shard`` frames of episodes whose seeds come from
``episode_seeds(seed, s, (k,))`` (:mod:`dstenv.data.sampling`), so every shard
depends only on its own task and the result is the same with 1 worker, K worker
processes or a Ray cluster. Each task writes ``DIR/<split>/shard-<k>.h5`` atomically
(:class:`~dstenv.data.shards.ShardWriter`); a rerun of the same command skips
shards that already exist with the same settings (resume), and refuses to mix in
shards made with other settings (:mod:`dstenv.data.resume`). ``DIR/manifest.json`` is
written last.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import sys
from collections.abc import Callable, Mapping
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from itertools import islice
from pathlib import Path
from typing import Any

from dstenv.config import CLIError
from dstenv.data.codec import DEFLATE_ENGINES
from dstenv.data.lifeline import sigterm_as_interrupt
from dstenv.data.lock import DatasetLocked, dataset_lock
from dstenv.data.manifest import MANIFEST_NAME, scan_shards, shard_entry, write_manifest
from dstenv.data.sampling import (SPLIT_BUCKETS, SPLITS, check_map_reuse, episode_seeds,
                                  frame_steps, iter_frames)
from dstenv.data.shards import FORMAT_VERSION, ShardError, ShardWriter

__all__ = ["GenerateError", "GenerateSpec", "ShardTask", "plan", "pipeline_config", "write_shard",
           "generate"]


class GenerateError(CLIError, RuntimeError):  # one line wherever it surfaces
    """Generation cannot proceed; the one-line message says why and what was kept."""


@dataclass(frozen=True)
class GenerateSpec:
    """What to generate (everything that determines the shards' content).

    Attributes:
        config: full :func:`dstenv.pipeline.default_config`-shaped configuration.
        frames: total frames over all splits.
        seed: base seed; episode seeds derive from it (:mod:`dstenv.data.sampling`).
        scenario: scenario name or file, recorded for provenance.
        split: ``"auto"`` (80/10/10 train/val/test frames) or one split name.
        frames_per_shard: frames per shard file (the last one of a split may be short).
        episode_length: steps per episode (one step = one LIDAR period, 0.1 s).
        stride: keep one frame every ``stride`` steps (10 = 1 s).
        warmup: first kept step of an episode.
        episodes_per_map: episodes driven on each procedural map with new traffic
            (:mod:`dstenv.data.sampling`); 1 builds a new city for every episode.
        masses: also store the raw ``(32, H, W)`` masses.
        quantize: probabilities as uint8 (error <= 1/510) instead of float32.
        compression: ``"gzip"`` or ``None`` (not ``"lzf"``: h5py's LZF filter does not
            write the same bytes twice); ``compression_level`` for gzip
            (1 with the ISA-L engine: ~0.6 ms and < 64 KB per 256x256 frame).
        deflate: gzip engine, ``"isal"`` or ``"zlib"`` (:mod:`dstenv.data.codec`).
    """

    config: Mapping[str, Any]
    frames: int
    seed: int = 0
    scenario: str = "default"
    split: str = "auto"
    frames_per_shard: int = 256
    episode_length: int = 200
    stride: int = 10
    warmup: int = 10
    episodes_per_map: int = 1
    masses: bool = False
    quantize: bool = True
    compression: str | None = "gzip"
    compression_level: int = 1
    deflate: str = "isal"

    def __post_init__(self) -> None:
        # checked before any work: a bad value must not surface after a whole shard
        if not 0 <= self.seed < 2**63:
            raise ValueError(f"--seed must be in [0, 2**63), got {self.seed}")
        if not 1 <= self.frames <= 10**10:
            raise ValueError(f"--frames must be in [1, 1e10], got {self.frames}")
        if not 1 <= (n := self.frames_per_shard) <= 100_000:
            raise ValueError(f"--frames-per-shard must be in [1, 100000], got {n}")
        if self.split != "auto" and self.split not in SPLITS:
            raise ValueError(f"unknown split {self.split!r}; choose auto, {', '.join(SPLITS)}")
        frame_steps(self.episode_length, self.stride, self.warmup)  # validates
        if not 1 <= (n := self.episodes_per_map) <= 10_000:
            raise ValueError(f"--episodes-per-map must be in [1, 10000], got {n}")
        if self.episodes_per_map > 1:  # before any folder or map is made
            check_map_reuse(self.config)
        _check_generation_config(self.config)
        if self.compression not in ("gzip", None):
            raise ValueError(
                f"compression {self.compression!r}: generate writes 'gzip' or none; lzf (h5py's "
                "filter) does not write the same bytes twice, so shards would differ between "
                "runs and resumes, and it is 1.5x bigger and 2.6x slower than gzip here "
                "(docs/throughput.md)" if self.compression == "lzf" else
                f"compression must be 'gzip' or None, got {self.compression!r}")
        if self.deflate not in DEFLATE_ENGINES:
            raise ValueError(f"unknown deflate engine {self.deflate!r}; choose "
                             f"{', '.join(DEFLATE_ENGINES)}")

    def meta(self) -> dict[str, Any]:
        """The settings as plain JSON data (without the config)."""
        return {k: v for k, v in dataclasses.asdict(self).items() if k != "config"}


def _check_generation_config(config: Mapping[str, Any]) -> None:
    """What would only fail inside the first shard, after its simulation: refused first."""
    if not config.get("frame", {}).get("labels", True):
        raise ValueError("frame.labels = false: generate stores every frame's labels; leave "
                         "frame.labels true (it is for RL envs that do not show them)")
    wm = config.get("world", {}).get("map", {})
    if wm.get("pool", 0):
        raise ValueError(f"world.map.pool = {wm['pool']}: generate draws a map per episode seed "
                         "(splits are disjoint map seeds); a pool would reuse its maps in "
                         "every split: leave it 0 (--episodes-per-map reuses maps within one)")
    from dstenv.sim.osm import check_osm_file

    check_osm_file(wm)


@dataclass(frozen=True)
class ShardTask:
    """One shard to produce: ``file`` (relative to the output directory) and its frames."""

    spec: GenerateSpec
    split: str
    index: int
    frames: int
    file: str = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "file", f"{self.split}/shard-{self.index:05d}.h5")

    def describe(self) -> dict[str, Any]:
        """The task as stored in the shard attribute ``task`` (compared on resume)."""
        d = self.spec.meta()
        d.pop("frames")
        d.update(split=self.split, index=self.index, frames=self.frames,
                 format_version=FORMAT_VERSION)
        return d


def split_frames(frames: int, split: str) -> dict[str, int]:
    """Frames per split: all in ``split``, or by the seed-space shares for ``"auto"``.

    ``"auto"`` deals the frames out in blocks of 10 in the buckets' shares (8 train,
    1 val, 1 test), the splits in their bucket order within a block, so one more frame
    adds one frame to one split: a dataset grown with a larger ``--frames`` keeps every
    shard it has (rounding each share would take a frame from train now and then).
    Multiples of 10 split as the shares say.
    """
    if split != "auto":
        return {split: frames}
    block, rest = divmod(frames, 10)
    counts = {}
    for s, (lo, hi) in sorted(SPLIT_BUCKETS.items(), key=lambda kv: kv[1][0]):
        lo, hi = lo // 10, hi // 10  # the buckets are whole tenths of the seed space
        counts[s] = block * (hi - lo) + min(max(rest - lo, 0), hi - lo)
    return {s: n for s, n in counts.items() if n > 0}


def plan(spec: GenerateSpec) -> list[ShardTask]:
    """All shard tasks of a generation, in a fixed order."""
    size = spec.frames_per_shard
    return [ShardTask(spec, split, k, min(size, n - start))
            for split, n in split_frames(spec.frames, spec.split).items()
            for k, start in enumerate(range(0, n, size))]


def pipeline_config(spec: GenerateSpec) -> dict[str, Any]:
    """The configuration a shard of ``spec`` is simulated with (and records)."""
    config = json.loads(json.dumps(spec.config))
    if spec.masses:
        config.setdefault("frame", {})["masses"] = True
    return config


def write_shard(task: ShardTask, out: str | Path,
                progress: Callable[[int], None] | None = None) -> dict[str, Any]:
    """Simulate the task's frames and write its shard atomically.

    Returns:
        the shard's manifest entry (:func:`dstenv.data.manifest.shard_entry`).
    """
    from dstenv.pipeline import Pipeline

    spec, out = task.spec, Path(out)
    config = pipeline_config(spec)
    attrs = {"config": config, "seed": spec.seed, "split": task.split, "shard_index": task.index,
             "scenario": spec.scenario, "task": task.describe()}
    frames = iter_frames(lambda: Pipeline(config), episode_seeds(spec.seed, task.split,
                         (task.index,)), spec.episode_length, spec.stride, spec.warmup,
                         spec.episodes_per_map)
    with ShardWriter(out / task.file, attrs, quantize=spec.quantize, masses=spec.masses,
                     compression=spec.compression,
                     compression_opts=spec.compression_level,
                     deflate=spec.deflate) as writer:
        for frame in islice(frames, task.frames):
            writer.add(frame)
            if progress is not None:
                progress(1)
    return shard_entry(out, out / task.file)


def generate(spec: GenerateSpec, out: str | Path, workers: int = 1, ray_address: str | None = None,
             progress: bool = True, force_unlock: bool = False) -> dict[str, Any]:
    """Generate (or resume) a dataset directory and write its manifest.

    Args:
        spec: what to generate.
        out: output directory (created if needed).
        workers: local worker processes (spawned); with Ray, CPUs of a local Ray.
        ray_address: ``None`` for no Ray, ``"local"`` to start a local Ray, else the
            address of a running cluster (``"auto"``, ``"ray://head:10001"``...).
        progress: show a tqdm bar (frames, frames/s) on stderr.
        force_unlock: take the folder's lock (:mod:`dstenv.data.lock`) even if another
            owner holds it.

    Returns:
        the manifest.

    Raises:
        GenerateError: unwritable output, settings clash with existing shards, or a
            failed shard (finished shards are kept; rerun to resume).
    """
    out = Path(out)
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    if out.exists() and not out.is_dir():
        raise GenerateError(f"output directory {out} is a file; give a folder name")
    if ray_address is not None:
        from dstenv.data.ray_backend import check_ray_address

        check_ray_address(ray_address)  # before the folder: a wrong one failed minutes later
    with contextlib.ExitStack() as stack:
        try:  # one writer per folder, even where HDF5 file locking is off (NFS, Lustre)
            stack.enter_context(dataset_lock(out, force_unlock))
        except DatasetLocked as exc:
            raise GenerateError(str(exc)) from None
        except OSError as exc:
            raise GenerateError(f"output directory {out} is not writable: "
                                f"{exc.strerror or exc}") from None
        return _generate(spec, out, workers, ray_address, progress)


def _generate(spec: GenerateSpec, out: Path, workers: int, ray_address: str | None,
              progress: bool) -> dict[str, Any]:
    from tqdm import tqdm

    from dstenv.data.resume import prepare

    tasks = plan(spec)
    done, todo = prepare(out, tasks)
    kept = sum(e["frames"] for e in done.values())
    if progress and done:  # else a rerun looks like a run that did the work again
        listed = (out / MANIFEST_NAME).is_file()
        print(f"dstenv generate: {out}: " + (
            f"all {kept} frames are there already" + (
                " (a finished run with these settings): nothing to generate" if listed
                else ": nothing to generate, only their manifest.json to write")
            if not todo else
            f"resuming: {len(done)} of {len(tasks)} shard(s), {kept} of {spec.frames} frames, "
            "are there already"), file=sys.stderr)
    # resumed frames count as initial, so frames/s is the rate of this run only
    bar = tqdm(total=spec.frames, initial=kept, unit="frame", disable=not progress or not todo,
               dynamic_ncols=True, desc="generate", smoothing=0.1)
    try:
        with sigterm_as_interrupt():  # SIGTERM cleans up like Ctrl-C (workers, partials)
            if ray_address is not None:
                from dstenv.data.ray_backend import run_ray

                results = run_ray(todo, out, ray_address, workers, bar.update)
            elif workers == 1 or len(todo) <= 1:
                results = _run_serial(todo, out, bar.update)
            else:
                from dstenv.data.pool_backend import run_pool

                results = run_pool(todo, out, workers, bar.update)
    except BrokenProcessPool:
        n = len(scan_shards(out))
        raise GenerateError(f"a worker process died (killed by the system: out of memory?); "
                            f"{n} finished shard{'' if n == 1 else 's'} kept in {out}; rerun "
                            "the same command to resume, with fewer --workers if memory is "
                            "short") from None
    except (OSError, ShardError) as exc:
        n = len(scan_shards(out))
        raise GenerateError(f"{exc}; {n} finished shard{'' if n == 1 else 's'} kept in {out}, "
                            "rerun the same command to resume") from None
    finally:
        bar.close()
    done.update(results)
    return write_manifest(out, [done[t.file] for t in tasks], meta={"generate": spec.meta(),
                                                                  "config": spec.config})


def _run_serial(todo: list[ShardTask], out: Path, update: Callable[[int], None]
                ) -> dict[str, dict[str, Any]]:
    return {t.file: write_shard(t, out, update) for t in todo}
