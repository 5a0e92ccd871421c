"""Learning curves: binning of training episodes, reference lines, the PNG."""

from __future__ import annotations

import math

import numpy as np

import curves

HEADER = "timesteps,wall_s,env,return,length,success,collision,off_road,progress_m\n"


def _run(path, rows):
    path.mkdir()
    (path / "episodes.csv").write_text(HEADER + "".join(
        f"{t},0,0,1.0,10,{s},{c},{o},5.0\n" for t, s, c, o in rows))
    return path


def test_binned_rates_by_hand(tmp_path) -> None:
    run = _run(tmp_path / "a", [(50, 1, 0, 0), (100, 0, 1, 0), (150, 0, 0, 1), (250, 1, 0, 0),
                                (400, 1, 0, 0)])
    r = curves.binned_rates(run, 100, 300)
    # bins (0, 100], (100, 200], (200, 300]; the episode at step 400 is past the end
    assert r["episodes"].tolist() == [2, 1, 1]
    assert r["success"].tolist() == [0.5, 0.0, 1.0]
    assert r["collision"].tolist() == [0.5, 0.0, 0.0]
    assert r["off_road"].tolist() == [0.0, 1.0, 0.0]
    empty = curves.binned_rates(run, 100, 600)
    assert math.isnan(empty["success"][4])  # no episode ended in (400, 500]


def test_plot_writes_png_with_references(tmp_path) -> None:
    a = _run(tmp_path / "a", [(t, t % 2, 0, 0) for t in range(10, 400, 10)])
    b = _run(tmp_path / "b", [(t, 1, 0, 0) for t in range(10, 300, 15)])
    ref = tmp_path / "eval.csv"
    ref.write_text("policy,seed,episode_return,length,collision,off_road,arrived,progress,"
                   "success\nrandom,1,0,1,True,False,False,0,False\n"
                   "random,2,0,1,False,False,False,0,True\n")
    assert curves.reference_rates([str(ref)]) == {
        "random": {"success": 0.5, "collision": 0.5, "off_road": 0.0}}
    out = curves.main(["--runs", str(a), str(b), "--reference", str(ref), "--bin", "100",
                       "--out", str(tmp_path / "c.png")])
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert np.isfinite(curves.binned_rates(b, 100, 290)["success"]).all()


def test_references_of_several_files_are_never_pooled(tmp_path) -> None:
    import pytest

    head = "policy,seed,episode_return,length,collision,off_road,arrived,progress,success\n"
    one, two = tmp_path / "cfg-a.csv", tmp_path / "cfg-b.csv"
    one.write_text(head + "grid,1,0,1,True,False,False,0,False\n")
    two.write_text(head + "grid,1,0,1,False,False,False,0,True\n")
    refs = curves.reference_rates([str(one), str(two)])
    assert refs["grid (cfg-a)"]["collision"] == 1.0 and refs["grid (cfg-b)"]["collision"] == 0.0
    bad = tmp_path / "episodes.csv"  # a training log given by mistake
    bad.write_text("timesteps,success,collision,off_road\n10,1,0,0\n")
    with pytest.raises(ValueError, match="not an evaluate.py --csv file .no column 'policy'"):
        curves.reference_rates([str(bad)])
    run = _run(tmp_path / "r", [])
    with pytest.raises(ValueError, match="has no finished episode yet"):
        curves.main(["--runs", str(run), "--out", str(tmp_path / "c.png")])


def test_a_run_given_twice_or_runs_of_other_envs_are_not_one_curve(tmp_path, capsys) -> None:
    """Attack 18: 'min..max over 2 seeds' of one run; action.repeat 1 and 3 pooled."""
    import json

    import pytest

    rows = [(t, 1, 0, 0) for t in range(10, 300, 10)]
    a, b, c = (_run(tmp_path / n, rows) for n in ("a", "b", "c"))
    base = {"env_id": "DSTGrid-Occluded-v0", "env_config": "", "max_episode_steps": 0,
            "map_pool": 50, "seed": 0, "learning_rate": 3e-4}
    for run, extra in ((a, {}), (b, {"seed": 1, "learning_rate": 1e-3}),
                       (c, {"seed": 2, "env_config": '{"action": {"repeat": 3}}'})):
        (run / "model.json").write_text(json.dumps({"args": {**base, **extra}}))
    out = str(tmp_path / "c.png")
    with pytest.raises(ValueError, match=r"--runs: .*a is given twice"):
        curves.main(["--runs", str(a), str(a), "--bin", "100", "--out", out])
    with pytest.raises(ValueError, match=r"learnt in other envs \(--env-config '' vs "):
        curves.main(["--runs", str(a), str(c), "--bin", "100", "--out", out])
    curves.main(["--runs", str(a), str(b), "--bin", "100", "--out", out])  # seeds: a note
    assert "differ in --learning-rate (0.0003 vs 0.001)" in capsys.readouterr().out
    for other in (tmp_path / "x", tmp_path / "y"):  # two files of one stem: their paths
        other.mkdir()
        (other / "eval.csv").write_text("policy,seed,collision,off_road,success\n"
                                        f"grid,1,{other.name == 'x'},False,True\n")
    refs = curves.reference_rates([str(tmp_path / "x/eval.csv"), str(tmp_path / "y/eval.csv")])
    assert sorted(refs) == [f"grid ({tmp_path}/x/eval.csv)", f"grid ({tmp_path}/y/eval.csv)"]
