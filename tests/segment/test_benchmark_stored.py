"""``dstenv benchmark`` on simulated shards without a train split (evaluation only)."""

from __future__ import annotations

import numpy as np
import pytest

from dstenv.segment.benchmark import run_benchmark
from dstenv.segment.presets import preset_config
from dstenv.segment.shardindex import split_index, stored_episodes


def _generate(out, stride, warmup):
    from dstenv.data.generate import GenerateSpec, generate
    from dstenv.data.sampling import scenario_config

    spec = GenerateSpec(
        # sparse beams with dropout: each sweep misses cells an earlier one saw, so the
        # filter history observes more than the last sweep however the ego moves
        config=scenario_config(None, {"grid": {"height": 32, "width": 32},
                                      "lidar": {"beams": 120, "dropout": 0.3}}),
        frames=6, seed=3,
        scenario="default", split="test", frames_per_shard=8, episode_length=6, stride=stride,
        warmup=warmup,
    )
    generate(spec, out, progress=False)
    return out


def _run(data, out):
    cfg = preset_config("tiny", {"models": [], "tune": {"params": {"alpha": 0.3}}})
    return run_benchmark(cfg, out, data_dir=data, progress=False, log=lambda m: None)


def test_every_step_stored_rebuilds_episodes_and_scores_presets(tmp_path):
    data = _generate(tmp_path / "data", stride=1, warmup=0)
    frames, config = split_index(sorted((data / "test").glob("*.h5")))
    episodes, reason = stored_episodes(frames, config)
    assert reason is None and len(episodes) == 1
    ep, steps = episodes[0]
    assert steps.tolist() == [0, 1, 2, 3, 4, 5] and ep.sensor.shape == (6, 32, 32)
    assert np.array_equal(ep.steps, np.arange(6))
    res = _run(data, tmp_path / "out")
    segs = res["segmenters"]
    assert list(segs) == ["dst (default)", "dst (paper)", "dst-free", "dst-tuned",
                          "dst-complete"]
    assert res["unscored"] == {} and res["data"]["source"] == "sim"
    assert res["data"]["evaluation_only"] and res["histories"] == {}
    assert res["data"]["observed_definition"] == "history" and res["preset"] is None
    assert len({v["all"]["cells"] for v in segs.values()}) == 1
    # the stored frames' filter history gives observed cells beyond the visible ones
    d = segs["dst (default)"]
    assert d["visible"]["cells"] < d["observed"]["cells"] <= d["all"]["cells"]
    assert (tmp_path / "out" / "figures" / "examples.png").stat().st_size > 0


def test_strided_frames_score_only_the_stored_betp(tmp_path):
    data = _generate(tmp_path / "data", stride=2, warmup=1)
    res = _run(data, tmp_path / "out")
    # dst-complete runs on the stored BetP (the generation parameters)
    assert list(res["segmenters"]) == ["dst (default)", "dst-free", "dst-complete"]
    assert set(res["unscored"]) == {"dst (paper)", "dst-tuned"}
    assert res["data"]["observed_definition"] == "visible"
    d = res["segmenters"]["dst (default)"]
    assert d["visible"]["cells"] == d["observed"]["cells"]
    assert "stores steps 1, 3, 5" in res["unscored"]["dst-tuned"]
    assert "## Not scored" in (tmp_path / "out" / "results.md").read_text()


def test_no_test_split_is_an_error(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="empty: no manifest.json and no shard files"):
        _run(tmp_path / "empty", tmp_path / "out")


def test_a_benchmark_folder_refuses_other_data(tmp_path):
    # its trained networks and results belong to the data it was made with: resuming it
    # on other data would score them on data they never saw and replace the results
    from dstenv.data.manifest import data_identity

    a = _generate(tmp_path / "a", stride=1, warmup=0)
    b = _generate(tmp_path / "b", stride=2, warmup=1)
    assert data_identity(a) != data_identity(b)
    import shutil

    shutil.copytree(a, tmp_path / "a-copy")
    assert data_identity(tmp_path / "a-copy") == data_identity(a)  # where it lives: no matter
    out = tmp_path / "out"
    _run(a, out)
    _run(tmp_path / "a-copy", out)  # the same data: resumes
    before = (out / "results.json").read_bytes()
    with pytest.raises(ValueError, match="holds a benchmark of other data .*choose another --out"):
        _run(b, out)
    assert (out / "results.json").read_bytes() == before
    # a run that failed before making anything does not bind its folder to its data
    from dstenv.segment.benchmark import _DATA_RECORD, _same_data

    failed = tmp_path / "failed"
    failed.mkdir()
    _same_data(failed, b)  # recorded, then the run failed: nothing else was written
    _same_data(failed, a)  # the corrected rerun goes on
    assert str(a.resolve()) in (failed / _DATA_RECORD).read_text()
