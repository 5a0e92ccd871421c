"""compare.py: two drivers episode by episode on the same seeds (exact McNemar)."""

from __future__ import annotations

import pytest
from scipy.stats import binomtest

import compare
from conftest import BASELINES

RESULTS = BASELINES.parent / "benchmarks" / "results" / "rl"


@pytest.mark.parametrize("only_a, only_b", [(9, 25), (7, 9), (0, 5), (3, 3), (37, 7)])
def test_mcnemar_is_the_exact_binomial_test_of_the_discordant_episodes(only_a, only_b):
    expected = binomtest(only_a, only_a + only_b, 0.5).pvalue
    assert compare.mcnemar_p(only_a, only_b) == pytest.approx(expected, rel=1e-12)
    assert compare.mcnemar_p(only_b, only_a) == compare.mcnemar_p(only_a, only_b)
    assert compare.mcnemar_p(0, 0) == 1.0


def test_compare_counts_discordant_episodes_on_common_seeds() -> None:
    def ep(success: bool, collision: bool) -> dict:
        return {"success": success, "collision": collision, "off_road": False}

    a = {1: ep(True, False), 2: ep(True, False), 3: ep(False, True), 4: ep(True, False)}
    b = {1: ep(False, True), 2: ep(True, False), 3: ep(True, False), 5: ep(True, False)}
    res = compare.compare(a, b)
    assert res["episodes"] == 3  # seeds 1, 2, 3
    assert res["success"] == {"a": 2 / 3, "b": 2 / 3, "only_a": 1, "only_b": 1, "p": 1.0}
    assert (res["collision"]["only_a"], res["collision"]["only_b"]) == (1, 1)
    with pytest.raises(ValueError, match="share no seed"):
        compare.compare({1: ep(True, False)}, {2: ep(True, False)})


def test_committed_evaluations_compare_as_the_readme_says() -> None:
    grid = str(RESULTS / "eval-grid-r3.csv")
    ppo = compare.main(["--a", grid, "--b", str(RESULTS / "eval-ppo-route-s0-450k.csv")])
    assert ppo["episodes"] == 100 and ppo["a"] == "rule-based (grid)"
    assert (ppo["success"]["only_a"], ppo["success"]["only_b"]) == (25, 9)
    assert ppo["success"]["p"] < 0.01 < ppo["collision"]["p"]
    same = compare.main(["--a", grid, "--b", str(RESULTS / "eval-ppo-residual-p90-s0-300k.csv")])
    assert all(same[k]["only_a"] == same[k]["only_b"] == 0 for k in compare.OUTCOMES)


def test_bad_files_are_named(tmp_path) -> None:
    with pytest.raises(FileNotFoundError, match="nope.csv: no such file"):
        compare.read_episodes(str(tmp_path / "nope.csv"))
    bad = tmp_path / "bad.csv"
    bad.write_text("a,b\n1,2\n")
    with pytest.raises(ValueError, match="bad.csv: not an evaluate.py --csv file"):
        compare.read_episodes(str(bad))
    two = tmp_path / "two.csv"
    two.write_text("policy,seed,success,collision,off_road\nx,1,True,False,False\n"
                   "y,1,False,True,False\n")
    with pytest.raises(ValueError, match="holds 2 policies"):
        compare.read_episodes(str(two))
    with pytest.raises(ValueError, match="no policy 'z'"):
        compare.read_episodes(str(two), "z")
    assert compare.read_episodes(str(two), "y") == (
        "y", {1: {"success": False, "collision": True, "off_road": False}})


@pytest.mark.parametrize("body, message", [
    ("x,abc,True,False,False\n", "two.csv, line 2: seed 'abc' is not an integer"),
    ("x,1,True,nope,False\n", "two.csv, line 2: collision 'nope' is not True or False"),
    ("x,1,True,False,False\nx,1,False,False,False\n", "line 3: seed 1 of 'x' a second time"),
    ("x,1,True\n", "line 2: collision None is not True or False"),
])
def test_bad_rows_are_named_with_their_line(tmp_path, body, message) -> None:
    path = tmp_path / "two.csv"
    path.write_text("policy,seed,success,collision,off_road\n" + body)
    with pytest.raises(ValueError, match=message):
        compare.read_episodes(str(path))


def test_a_binary_file_is_named(tmp_path) -> None:
    path = tmp_path / "bin.csv"
    path.write_bytes(bytes(range(256)) * 4)
    with pytest.raises(ValueError, match="bin.csv: not a CSV text file"):
        compare.read_episodes(str(path))


def test_files_scored_in_other_envs_are_not_paired(tmp_path, capsys) -> None:
    """Attack 18: a McNemar table of two drivers scored in different env configs (every
    row now records the env; a file without it gets a note)."""
    from rl_common import EnvArgs, EpisodeResult, write_results_csv

    ep = EpisodeResult(seed=10000, episode_return=1.0, length=10, collision=False, off_road=False,
                       arrived=True, progress=50.0, success=True)
    a, b, c = tmp_path / "a.csv", tmp_path / "b.csv", tmp_path / "c.csv"
    write_results_csv(a, [("grid", [ep])], EnvArgs())
    write_results_csv(b, [("grid", [ep])], EnvArgs(env_config='{"action": {"repeat": 3}}'))
    write_results_csv(c, [("ppo", [ep])], EnvArgs(env_config=' { } '))
    header, row = a.read_text().splitlines()
    assert header.endswith(",env_id,env_config,max_episode_steps")
    assert row.endswith(",DSTGrid-Occluded-v0,{},0")
    assert b.read_text().splitlines()[1].endswith(',"{""action"":{""repeat"":3}}",0')
    with pytest.raises(ValueError, match=r"A and B were scored in different envs \(env_config: "
                                         r"\{\} vs \{\"action\":\{\"repeat\":3\}\}\)"):
        compare.main(["--a", str(a), "--b", str(b)])
    assert compare.main(["--a", str(a), "--b", str(c)])["episodes"] == 1  # the same env
    old = RESULTS / "eval-grid-r3.csv"  # written before the env columns
    compare.main(["--a", str(old), "--b", str(c)])
    assert "note: A does not record its env" in capsys.readouterr().out
