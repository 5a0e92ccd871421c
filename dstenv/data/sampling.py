"""Which episodes to simulate: disjoint split seeds and frame sampling from a Pipeline.

Splits from disjoint map seeds
------------------------------
An episode's seed is its map seed (``Pipeline.reset(seed)`` builds the map from it).
The seed space is partitioned *by hashing the seed itself*::

    bucket = blake2b(seed as 8 little-endian bytes, key "dstenv-split") mod 100
    train: bucket 0-79   val: bucket 80-89   test: bucket 90-99

A split draws candidate seeds from its own random stream and keeps only those whose
bucket belongs to it. The split is therefore a property of the map seed, not of the
run: a test map never appears in any training set, whatever ``--seed``, ``--frames``
or worker count produced them (also across separate runs and the streaming dataset).
Scenarios with a fixed map (an OSM file) have one map only; their splits differ in
traffic and ego route, not in map.

Several episodes per map
------------------------
Building a procedural city costs about as much as 100 simulation steps. With
``episodes_per_map = E > 1`` each map seed serves ``E`` episodes: the first one is
exactly ``Pipeline.reset(seed)``; episode ``k >= 1`` drives the same map with
new traffic, ego route, LIDAR noise and map error drawn from
:func:`traffic_seed` ``(seed, k)``. Frames keep the map seed in ``frame.seed`` (the
split stays a property of the map); ``frame.step`` restarts at each episode, so
``k`` is the number of step restarts since the seed changed.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from dstenv.frame import Frame

__all__ = [
    "SPLITS",
    "SPLIT_BUCKETS",
    "SEED_LIMIT",
    "split_of_seed",
    "episode_seeds",
    "frame_steps",
    "iter_frames",
    "traffic_seed",
    "check_map_reuse",
    "scenario_config",
]

SPLITS: tuple[str, ...] = ("train", "val", "test")
#: split -> half-open range of hash buckets (out of 100). Fixed forever: changing it
#: would let test maps of old datasets leak into new training sets.
SPLIT_BUCKETS: dict[str, tuple[int, int]] = {"train": (0, 80), "val": (80, 90), "test": (90, 100)}
#: Episode seeds are drawn from ``[0, SEED_LIMIT)`` (fits every RNG's seed type).
SEED_LIMIT = 2**32


def split_of_seed(seed: int) -> str:
    """The split a map seed belongs to (see the module docstring)."""
    digest = hashlib.blake2b(
        int(seed).to_bytes(8, "little", signed=False), digest_size=8, key=b"dstenv-split"
    ).digest()
    bucket = int.from_bytes(digest, "little") % 100
    for name, (lo, hi) in SPLIT_BUCKETS.items():
        if lo <= bucket < hi:
            return name
    raise AssertionError(bucket)  # pragma: no cover - buckets cover 0..99


def episode_seeds(base_seed: int, split: str | None, stream: Sequence[int]) -> Iterator[int]:
    """Endless, reproducible episode seeds of one split.

    Args:
        base_seed: the user's seed (``--seed``).
        split: ``"train"``, ``"val"``, ``"test"``, or ``None`` for any split.
        stream: integers naming an independent stream, e.g. ``(shard_index,)`` or
            ``(rank, worker_id, epoch)``; different streams give unrelated seeds.

    Yields:
        ints in ``[0, SEED_LIMIT)`` whose :func:`split_of_seed` is ``split``.
    """
    if split is not None and split not in SPLITS:
        raise ValueError(f"unknown split {split!r}; choose from {', '.join(SPLITS)}")
    tag = -1 if split is None else SPLITS.index(split)
    ss = np.random.SeedSequence(_entropy(int(base_seed), [tag + 1, *(int(s) for s in stream)]))
    rng = np.random.default_rng(ss)
    while True:
        for seed in rng.integers(0, SEED_LIMIT, size=64, dtype=np.uint64).tolist():
            if split is None or split_of_seed(seed) == split:
                yield int(seed)


def frame_steps(episode_length: int, stride: int, warmup: int) -> list[int]:
    """Steps of an episode whose frames are kept: ``warmup, warmup + stride, ... < length``.

    Step 0 is the frame returned by ``reset``. Raises ValueError if none is kept.
    """
    if stride < 1:
        raise ValueError(f"stride must be >= 1 step, got {stride}")
    if warmup < 0:
        raise ValueError(f"warmup must be >= 0 steps, got {warmup}")
    steps = list(range(warmup, episode_length, stride))
    if not steps:
        raise ValueError(f"episode length {episode_length} keeps no frame after a warmup of "
                         f"{warmup} steps: make the episode longer than the warmup")
    return steps


#: marks the entropy of a seed of 2**32 and more (:func:`_entropy`)
_WIDE = 0x5EED_0B16


def _entropy(seed: int, rest: list[int]) -> list[int]:
    """SeedSequence entropy of ``seed`` then ``rest``. A seed below 2**32 is one word, as
    it always was (every such stream is unchanged); a larger one is its 32-bit words, their
    count and a marker. (Given as one int, numpy splits it into words and pads short lists
    with zeros: seed 2**32 with stream (0,) was seed 0 with stream (1,).)"""
    if seed < 2**32:
        return [seed, *rest]
    words = []
    while seed:
        words.append(seed & 0xFFFF_FFFF)
        seed >>= 32
    return [*words, len(words), *rest, _WIDE]


def traffic_seed(map_seed: int, episode: int) -> int:
    """Seed of episode ``episode >= 1`` on the map of ``map_seed`` (module docstring)."""
    ss = np.random.SeedSequence([int(map_seed), int(episode), 0x7AFF1C])
    return int(ss.generate_state(1, np.uint64)[0] % SEED_LIMIT)


def iter_frames(
    make_pipeline: Callable[[], Any],
    seeds: Iterator[int],
    episode_length: int,
    stride: int,
    warmup: int,
    episodes_per_map: int = 1,
) -> Iterator[Frame]:
    """Frames of consecutive autopilot episodes, one every ``stride`` steps.

    Args:
        make_pipeline: builds the :class:`dstenv.pipeline.Pipeline` (called once).
        seeds: episode seeds, e.g. from :func:`episode_seeds`.
        episode_length: steps per episode (including the reset frame, step 0).
        stride: keep one frame every ``stride`` steps.
        warmup: first kept step (lets the DST grid accumulate evidence).
        episodes_per_map: episodes driven on each map (module docstring); above 1
            the pipeline must be a procedural ``"city"`` one.

    Yields:
        :class:`Frame` objects; ``frame.seed`` is the episode's map seed and
        ``frame.step`` the step index (set here if the pipeline leaves them at their
        defaults).
    """
    if episodes_per_map < 1:
        raise ValueError(f"episodes per map must be >= 1, got {episodes_per_map}")
    keep = set(frame_steps(episode_length, stride, warmup))
    last = max(keep)
    pipeline = make_pipeline()
    if episodes_per_map > 1:
        check_map_reuse(pipeline.config)
    for seed in seeds:
        frame = pipeline.reset(seed)
        yield from _episode(pipeline, frame, seed, keep, last)
        for k in range(1, episodes_per_map):  # the same map, new traffic
            frame = pipeline.reset(traffic_seed(seed, k), keep_map=True)
            yield from _episode(pipeline, frame, seed, keep, last)


def _episode(pipeline: Any, frame: Frame, seed: int, keep: set[int], last: int
             ) -> Iterator[Frame]:
    # steps between kept frames need no Frame (labels...): Pipeline.advance skips it
    advance = getattr(pipeline, "advance", None)
    for step in range(last + 1):
        if step > 0:
            if step in keep or advance is None:
                frame = pipeline.step(None)
            else:
                advance(None)
        if step in keep:
            frame.seed, frame.step = int(seed), step
            yield frame


def check_map_reuse(config: Mapping[str, Any]) -> None:
    """ValueError unless ``config`` drives a procedural city (several episodes per map)."""
    kind = config.get("world", {}).get("map", {}).get("kind")
    if config.get("source") != "city" or kind != "procedural":
        raise ValueError("episodes per map > 1 (--episodes-per-map) needs source 'city' with "
                         f"a procedural map (got source {config.get('source')!r}, map kind "
                         f"{kind!r}): give 1, or a procedural-city scenario")


def scenario_config(scenario: str | Path | Mapping[str, Any] | None = None,
                    overrides: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Full pipeline configuration from a scenario and overrides.

    Args:
        scenario: a shipped scenario name, a ``.toml`` path, a (partial) config dict,
            or ``None`` for the defaults.
        overrides: applied last (e.g. ``{"grid": {"height": 64, "width": 64}}``).

    Returns:
        The validated configuration of :func:`dstenv.config.build_config`.

    Raises:
        dstenv.config.ConfigError: unknown scenario or key, or a bad value (named).
    """
    from dstenv.config import build_config

    if isinstance(scenario, Mapping):
        return build_config(None, ("config", scenario), ("override", overrides))
    return build_config(scenario, ("override", overrides))
