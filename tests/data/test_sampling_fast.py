"""Generation fast paths with the real pipeline: skipped frames, several episodes per map."""

from __future__ import annotations

import hashlib
from itertools import islice

import numpy as np
import pytest

from dstenv.data import generate as gen
from dstenv.data.sampling import (
    iter_frames, scenario_config, split_of_seed, traffic_seed,
)
from dstenv.data.shards import ShardReader
from dstenv.pipeline import Pipeline

CONFIG = scenario_config(None, {"grid": {"height": 48, "width": 40}})
FIELDS = ("pignistic", "pignistic_prev", "labels", "visible", "sensor", "gis", "ego_pose")


def _same(a, b):
    for name in FIELDS:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert (a.time, a.seed, a.step) == (b.time, b.seed, b.step)


def test_skipped_steps_give_the_frames_of_a_full_step_loop():
    # iter_frames advances without building frames between kept steps (Pipeline.advance)
    got = list(iter_frames(lambda: Pipeline(CONFIG), iter([11]), 9, 4, 2))
    p = Pipeline(CONFIG)
    full = [p.reset(11)] + [p.step() for _ in range(8)]
    assert [f.step for f in got] == [2, 6]
    for f in got:
        _same(f, full[f.step])
    # pignistic_prev is BetP of the step before, also when that step was skipped
    np.testing.assert_array_equal(got[1].pignistic_prev, full[5].pignistic)


def test_traffic_seed_is_deterministic_and_distinct():
    assert traffic_seed(5, 1) == traffic_seed(5, 1)
    seeds = {traffic_seed(s, k) for s in range(20) for k in range(1, 4)}
    assert len(seeds) == 60 and all(0 <= s < 2**32 for s in seeds)


def test_episodes_per_map_reuse_the_map_with_new_traffic():
    from dstenv.sim.world import World

    frames = list(islice(iter_frames(lambda: Pipeline(CONFIG), iter([3, 8]), 6, 2, 1,
                                     episodes_per_map=3), 10))
    assert [f.step for f in frames] == [1, 3, 5] * 3 + [1]
    assert [f.seed for f in frames] == [3] * 9 + [8]  # the map seed, whatever the episode
    # episode 0 is Pipeline.reset(map seed) itself
    first = Pipeline(CONFIG)
    ep0 = [first.reset(3)] + [first.step() for _ in range(5)]
    for f in frames[:3]:
        _same(f, ep0[f.step])
    # episode k >= 1: the same map (same object content), traffic from traffic_seed(3, k)
    for k in (1, 2):
        world = World(CONFIG["world"], 0, world_map=first.world.map)
        p = Pipeline(CONFIG, world=world)
        ep = [p.reset(traffic_seed(3, k))] + [p.step() for _ in range(5)]
        for f in frames[3 * k:3 * k + 3]:
            g = ep[f.step]
            g.seed = 3
            _same(f, g)
    # new traffic and ego route on the same map
    assert not np.allclose(frames[0].ego_pose, frames[3].ego_pose)
    assert not np.allclose(frames[3].ego_pose, frames[6].ego_pose)


def test_episodes_per_map_needs_a_procedural_city():
    osm = scenario_config("osm", {"grid": {"height": 48, "width": 40}})
    with pytest.raises(ValueError, match="procedural"):
        next(iter_frames(lambda: Pipeline(osm), iter([1]), 6, 2, 1, episodes_per_map=2))
    with pytest.raises(ValueError, match="episodes per map"):
        next(iter_frames(lambda: Pipeline(CONFIG), iter([1]), 6, 2, 1, episodes_per_map=0))


@pytest.mark.slow
def test_generate_with_map_reuse_is_deterministic_over_workers(tmp_path):
    spec = gen.GenerateSpec(config=CONFIG, frames=24, seed=2, split="auto", frames_per_shard=6,
                            episode_length=8, stride=3, warmup=1, episodes_per_map=2)
    gen.generate(spec, tmp_path / "a", workers=1, progress=False)
    gen.generate(spec, tmp_path / "b", workers=2, progress=False)
    digest = {d: {p.relative_to(tmp_path / d).as_posix(): hashlib.sha256(p.read_bytes())
                  .hexdigest() for p in sorted((tmp_path / d).rglob("*.h5"))} for d in "ab"}
    assert digest["a"] == digest["b"] and len(digest["a"]) == 6
    for path in sorted((tmp_path / "a").rglob("*.h5")):
        with ShardReader(path) as r:
            assert r.attrs["task"]["episodes_per_map"] == 2
            assert all(split_of_seed(int(r[i].seed)) == r.attrs["split"] for i in range(len(r)))


def test_paper_protocol_sweeps_only_fused_steps_and_keeps_the_frames():
    # 1 fusion every 3 steps, one stored frame every 3 steps: steps 1, 2, 4, 5 only move
    # the world; the stored frames equal those of a plain step loop
    config = {**CONFIG, "protocol": {"update_every": 3}}
    sweeps = []

    def make():
        p = Pipeline(config)
        sweep = p.lidar.sweep
        p.lidar.sweep = lambda *a, **k: sweeps.append(1) or sweep(*a, **k)
        return p

    got = list(iter_frames(make, iter([11]), 7, 3, 3))
    assert [f.step for f in got] == [3, 6] and len(sweeps) == 3  # steps 0, 3, 6
    p = Pipeline(config)
    full = [p.reset(11)] + [p.step() for _ in range(6)]
    for f in got:
        _same(f, full[f.step])


def test_large_base_seeds_give_streams_of_their_own():
    from dstenv.data.sampling import episode_seeds

    def first(seed, stream):
        return list(islice(episode_seeds(seed, "train", stream), 4))

    # numpy took 2**32 as the words (0, 1) and padded short lists with zeros: seed 2**32's
    # shard 0 was seed 0's shard 1, episode for episode
    assert first(2**32, (0,)) != first(0, (1,))
    assert first(2**32, (0, 0, 0)) != first(0, (1, 0, 0, 0))
    assert first(2**64 + 5, (0,)) != first(5, (0, 1))
    # below 2**32 the streams are the ones every dataset so far was made with
    assert first(0, (1,))[0] == 2895938922 and first(2**32 - 1, (0,))[0] == 3259647241
