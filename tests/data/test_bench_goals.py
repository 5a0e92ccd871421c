"""The goal table of ``dstenv bench data``: rows and their printing (no timings here)."""

from __future__ import annotations

import math

from dstenv.data.bench_goals import _protocol, print_goals
from dstenv.data.sampling import scenario_config


def test_protocol_rows_follow_what_the_build_supports():
    config = scenario_config(None, {})
    proto = _protocol(config, False)
    if "protocol" in config:  # the paper protocol: one fusion per simulated second
        assert proto["protocol"]["update_every"] == 10
    else:
        assert proto is None


def test_print_goals_marks_missing_rows(capsys):
    rows = {
        "stride 10, paper protocol, 3-D LIDAR": {"value": None, "unit": "frames/h",
                                                 "goal": ">= 500,000", "note": "not here"},
        "DST update 256 x 256, one core": {"value": 0.512, "runs": [0.5, 0.512, 0.6],
                                           "unit": "ms", "goal": "<= 0.6"},
        "stride 10, 10 Hz fusion, 2-D LIDAR": {"value": 512345.0, "runs": [], "unit": "frames/h",
                                               "goal": ">= 500,000"},
    }
    print_goals(rows, 3)
    out = capsys.readouterr().out
    assert "median of 3" in out and "n/a" in out and "not here" in out
    assert "0.51" in out and "512,345" in out


def test_steady_rate_cancels_start_up(monkeypatch, tmp_path):
    from dstenv.data import bench_goals

    # a run costs 5 s of start-up plus 0.1 s per frame
    monkeypatch.setattr(bench_goals, "_generate_seconds",
                        lambda config, frames, workers, tmp, **kw: 5.0 + 0.1 * frames)
    r = bench_goals._generate_rates({}, 40, 2, tmp_path)
    assert r["steady"] == 36_000.0  # 10 frames/s, start-up gone
    assert r["short_run"] == 3600 * 40 / 9.0  # start-up included
    # a long run no slower than the short one (noise, tiny --quick counts): no rate
    monkeypatch.setattr(bench_goals, "_generate_seconds", lambda *a, **kw: 5.0)
    assert math.isnan(bench_goals._generate_rates({}, 40, 2, tmp_path)["steady"])


def test_generation_row_skips_runs_without_a_steady_rate(capsys):
    from dstenv.data.bench_goals import _generation_row

    runs = [{"steady": 4e5, "short_run": 3e5}, {"steady": float("nan"), "short_run": 2e5},
            {"steady": 6e5, "short_run": 1e5}]
    row = _generation_row(runs, 16, 2, ">= 500,000")
    assert row["value"] == 5e5 and row["runs"][1]["steady"] is None
    assert "median of the 2 of 3 runs" in row["note"] and "200,000" in row["note"]
    none = _generation_row([{"steady": float("nan"), "short_run": 1e5}], 16, 2, ">= 1")
    assert none["value"] is None and "without --quick" in none["note"]
    print_goals({"stride 10, 10 Hz fusion, 2-D LIDAR": none}, 1)
    out = capsys.readouterr().out
    assert "n/a" in out and "nan" not in out


def test_timed_generate_runs_the_documented_spec(tmp_path):
    """The one generate run every data benchmark times: seed 1, split train, a frame
    every ``stride`` steps from step ``stride``, shards of generate's default size."""
    import h5py

    from dstenv.data.bench_goals import timed_generate

    config = scenario_config(None, {"grid": {"height": 32, "width": 32}})
    wall, cpu = timed_generate(config, 4, 1, tmp_path / "out", stride=5)
    assert wall > 0 and cpu > 0
    shards = sorted((tmp_path / "out" / "train").glob("*.h5"))
    assert len(shards) == 1  # not one shard a frame or two: a fresh map a shard
    with h5py.File(shards[0]) as f:
        assert f["step"][:].tolist() == [5, 10, 15, 20]


def test_goal_rows_time_map_reuse_rows_with_episodes_per_map(monkeypatch):
    from dstenv.data import bench_goals

    calls = []

    def rates(cfg, frames, workers, tmp, **kw):
        calls.append((frames, kw))
        return {"short_run": 1.0, "steady": 2.0, "short_s": 1.0, "long_s": 2.0}

    monkeypatch.setattr(bench_goals, "_generate_rates", rates)
    monkeypatch.setattr(bench_goals, "_reset_ms", lambda: 50.0)
    monkeypatch.setattr(bench_goals, "_write_path_ms", lambda *a: {"cpu_ms": 0.8})
    monkeypatch.setattr(bench_goals, "_env_ratio", lambda steps: {"ratio": 6.0})
    monkeypatch.setattr(bench_goals, "_dst_ms", lambda: 0.5)
    rows = bench_goals.goal_rows(scenario_config(None, {}), 1, False)
    reuse = [k for k in rows if k.endswith(f"{bench_goals.MAP_REUSE} episodes per map")]
    assert len(reuse) == 3 and rows[reuse[0]]["goal"] == ">= 500,000"
    eps = [kw["episodes_per_map"] for _, kw in calls]
    assert eps.count(1) == eps.count(bench_goals.MAP_REUSE) > 0
    assert {f for f, _ in calls} == {2 * 256}  # a default shard per worker
    calls.clear()
    quick = bench_goals.goal_rows(scenario_config(None, {}), 1, True)
    assert not any("episodes per map" in k for k in quick)
    assert {kw["episodes_per_map"] for _, kw in calls} == {1}
