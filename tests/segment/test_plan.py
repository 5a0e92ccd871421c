"""Test drives and segmenter plans: several episodes per map, fixed parameters."""

import json

import numpy as np
import pytest

from dstenv.config import ConfigError
from dstenv.segment.plan import fixed_params, split_drives


def test_several_episodes_per_map_replay_and_score(tmp_path):
    """Regression: frames were keyed by (seed, step), which repeats across the episodes
    of one map, and the replay of episode k >= 1 raised 'not reproducible'."""
    from dstenv.data import ShardDataset
    from dstenv.data.generate import GenerateSpec, generate
    from dstenv.data.sampling import scenario_config
    from dstenv.segment.benchmark import run_benchmark
    from dstenv.segment.presets import preset_config

    spec = GenerateSpec(
        config=scenario_config(None, {"grid": {"height": 32, "width": 32}}), frames=6, seed=2,
        scenario="default", split="test", frames_per_shard=8, episode_length=8, stride=3,
        warmup=2, episodes_per_map=2,
    )
    generate(spec, tmp_path / "data", progress=False)
    ds = ShardDataset(tmp_path / "data", split="test")
    drives = split_drives(ds, no_train=False, progress=False, log=lambda m: None)
    keys = [ep.key for ep in drives.episodes]
    # 6 frames of 2 per episode: map A twice, then the first episode of map B
    twice = [s for s, k in keys if k == 1]
    assert len(keys) == 3 and len(twice) == 1 and (twice[0], 0) in keys
    # every drive (both episodes of map A were checked) against its own stored frames
    for ep in drives.episodes:
        assert ep.stored_x.shape[0] == len(ep.steps) == ep.labels.shape[0] == 2
    a0, a1 = (next(ep for ep in drives.episodes if ep.key == (twice[0], k)) for k in (0, 1))
    assert not np.array_equal(a0.poses, a1.poses)  # new traffic and route on the same map
    # and the benchmark on that data (evaluation only: no train split) scores every frame
    cfg = preset_config("tiny", {"models": [], "tune": {"params": {"alpha": 0.3}}})
    res = run_benchmark(cfg, tmp_path / "out", data_dir=tmp_path / "data", progress=False,
                        log=lambda m: None)
    assert res["data"]["test_frames"] == 6 and res["data"]["test_episodes"] == 3
    assert res["data"]["test_maps"] == 2


def test_fixed_params_take_what_results_json_prints(tmp_path):
    row = {"kind": "dst", "describe": {"name": "dst-tuned", "params": {"alpha": 0.2},
                                       "tuning": {"budget": 3}}}
    assert fixed_params(row, "tune.params") == {"alpha": 0.2}
    assert fixed_params(row["describe"], "tune.params") == {"alpha": 0.2}
    assert fixed_params({"alpha": 0.2}, "tune.params") == {"alpha": 0.2}
    with pytest.raises(ConfigError, match="tune.params: expected"):
        fixed_params({"tuning": {"budget": 3}}, "tune.params")
    # dst-complete's entry holds both its DST parameters and its box sizes: complete.params
    # takes the sizes (it used to pass the DST parameters to the completion: a TypeError)
    complete = {"kind": "baseline", "describe": {"name": "dst-complete",
                                                 "params": {"alpha": 0.2},
                                                 "completion": {"length_m": 4.0}}}
    assert fixed_params(complete, "complete.params", "completion") == {"length_m": 4.0}
    assert fixed_params(complete, "tune.params") == {"alpha": 0.2}
    with pytest.raises(ConfigError, match="complete.params: .* holding 'completion'"):
        fixed_params(row, "complete.params", "completion")


def test_cli_params_from_results_json(tmp_path):
    import argparse

    from dstenv.config import CLIError
    from dstenv.segment.bench_cli import _params_value

    res = {"segmenters": {"dst-tuned": {"describe": {"params": {"alpha": 0.4}}}}}
    path = tmp_path / "results.json"
    path.write_text(json.dumps(res))
    assert _params_value(f"@{path}", "tune.params", "dst-tuned") == res["segmenters"]["dst-tuned"]
    assert _params_value('{"params": {"alpha": 0.4}}', "tune.params", "dst-tuned") == {
        "params": {"alpha": 0.4}}
    with pytest.raises(CLIError, match="no 'dst-complete' row"):
        _params_value(f"@{path}", "complete.params", "dst-complete")
    with pytest.raises(CLIError, match="expected a JSON object"):
        _params_value("alpha", "tune.params", "dst-tuned")
    assert argparse  # the CLI path itself is exercised in tests/kitti/test_benchmark.py


def test_no_map_networks_fine_tune_on_the_map_free_training_frames(tmp_path):
    from pathlib import Path

    import torch

    from dstenv.data import ShardDataset
    from dstenv.segment.benchmark import run_benchmark
    from dstenv.segment.presets import preset_config
    from dstenv.segment.checkpoint import load_checkpoint

    with pytest.raises(ConfigError, match="no_map: epochs"):
        run_benchmark(preset_config("tiny", {"no_map": {"epochs": -1}}), tmp_path / "bad",
                      progress=False, log=lambda m: None)
    cfg = preset_config("tiny", {"data": {"overrides": {"gis": {"no_map_prob": 0.5}}},
                                 "no_map": {"epochs": 1}, "tune": {"enabled": False},
                                 "complete": {"enabled": False}})
    res = run_benchmark(cfg, tmp_path, progress=False, log=lambda m: None)
    train = ShardDataset(tmp_path / "data", split="train")
    idx = train.no_map_indices()
    assert 0 < len(idx) < len(train)
    for i in range(len(train)):  # exactly the frames whose GIS grid is all MapClass.NONE
        path, j = train.locate(i)
        from dstenv.data.reader import ShardReader

        with ShardReader(path) as r:
            assert (i in idx) == (not r.get(j, ["gis"])["gis"].any())
    row = res["segmenters"]["unet-light no-map"]
    assert row["kind"] == "learned" and row["describe"]["no_map_frames"] == len(idx)
    tuned = load_checkpoint(Path(row["describe"]["checkpoint"]) / "best.pt")
    base = load_checkpoint(tmp_path / "models" / "unet-light" / "best.pt")
    assert tuned["config"]["init"] == str(tmp_path / "models" / "unet-light" / "best.pt")
    assert any(not torch.equal(tuned["model"][k], base["model"][k]) for k in base["model"])
    # data with a map in every drive (a plain `dstenv generate`): the run goes on and says
    # why there is no map-free row (it used to stop after training with an error)
    cfg = preset_config("tiny", {"no_map": {"epochs": 1}, "tune": {"enabled": False},
                                 "complete": {"enabled": False}})
    res = run_benchmark(cfg, tmp_path / "mapped", progress=False, log=lambda m: None)
    assert "unet-light no-map" not in res["segmenters"] and "unet-light" in res["segmenters"]
    assert "no training drive was fused without a map" in res["unscored"]["unet-light no-map"]
