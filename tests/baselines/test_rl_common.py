"""Shared pieces of the RL baselines: arguments, wrappers, statistics, atomic files."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import gymnasium as gym
import pytest

from rl_common import (EnvArgs, EpisodeResult, atomic_write_text,
                       env_config, make_env, opt, parse_args, summarize, to_argv)

BASELINES = Path(__file__).resolve().parents[2] / "baselines"


@dataclass
class _Args:
    n: int = opt(1, "an int")
    rate: float = opt(0.5, "a float")
    name: str = opt("a", "a string")
    flag: bool = opt(True, "a bool")
    xs: list[int] = opt([1], "a list")


def test_parse_args_types_and_round_trip() -> None:
    a = parse_args(_Args, ["--n", "3", "--rate", "0.25", "--no-flag", "--xs", "4", "5"])
    assert a == _Args(n=3, rate=0.25, name="a", flag=False, xs=[4, 5])
    assert to_argv(a) == ["--n", "3", "--rate", "0.25", "--no-flag", "--xs", "4", "5"]
    assert parse_args(_Args, to_argv(a)) == a
    assert to_argv(_Args()) == []
    with pytest.raises(SystemExit):
        parse_args(_Args, ["--unknown", "1"])


def test_env_config_merges_user_flags_over_the_baseline_and_rejects_bad_json() -> None:
    args = EnvArgs(env_config='{"grid": {"height": 40}, "world": {"map": {"pool": 0}}}')
    own = {"world": {"map": {"pool": 50, "blocks_x": 3}}}
    assert env_config(args, own) == {"grid": {"height": 40},
                                     "world": {"map": {"pool": 0, "blocks_x": 3}}}
    assert env_config(EnvArgs()) == {}
    with pytest.raises(ValueError, match="--env-config"):
        env_config(EnvArgs(env_config="{grid"))
    with pytest.raises(ValueError, match="JSON object"):
        env_config(EnvArgs(env_config="[1]"))


def test_summarize_hand_computed() -> None:
    res = [EpisodeResult(0, 1.0, 10, True, False, False, 10.0, False),
           EpisodeResult(1, 2.0, 20, False, True, False, 20.0, False),
           EpisodeResult(2, 6.0, 30, False, False, False, 120.0, True)]
    s = summarize(res)
    assert s["success"] == pytest.approx(1 / 3)
    assert s["collision"] == pytest.approx(1 / 3) and s["off_road"] == pytest.approx(1 / 3)
    assert s["return"] == pytest.approx(3.0)
    # sample std of (1, 2, 6) = sqrt(14 / 2); standard error = that / sqrt(3)
    assert s["return_se"] == pytest.approx(math.sqrt(7.0) / math.sqrt(3.0))
    assert s["progress"] == pytest.approx(50.0) and s["length"] == pytest.approx(20.0)
    with pytest.raises(ValueError, match="no episodes"):
        summarize([])


def test_make_env_gives_the_registered_dict_observation(small_config: dict) -> None:
    import json

    env = make_env(EnvArgs(env_config=json.dumps(small_config)), monitor=True)
    assert isinstance(env.observation_space, gym.spaces.Dict)
    assert env.observation_space["grid"].shape == (4, 40, 40)
    assert env.unwrapped.get_action_meanings() == ["SLOWER", "IDLE", "FASTER"]
    env.reset(seed=3)
    for _ in range(400):
        _, _, terminated, truncated, info = env.step(2)
        if terminated or truncated:
            break
    # Monitor copies the env's episode outcome into info["episode"]
    ep = info["episode"]
    assert ep["is_success"] == info["is_success"] and ep["collision"] == info["collision"]
    assert ep["route_progress"] == pytest.approx(info["route_progress"])
    env.close()


def test_atomic_write_leaves_no_temp_file(tmp_path) -> None:
    target = tmp_path / "sub" / "out.txt"
    atomic_write_text(target, "one")
    atomic_write_text(target, "two")
    assert target.read_text() == "two"
    assert [p.name for p in target.parent.iterdir()] == ["out.txt"]


@pytest.mark.parametrize("script, argv, message", [
    ("ppo_grid.py", ["--extractor", "nope", "--out", "out"], "--extractor: expected one of"),
    ("ppo_grid.py", ["--residual", "pilot", "--out", "out"], "--residual: expected"),
    ("ppo_grid.py", ["--residual", "grid", "--residual-p-rule", "1", "--out", "out"],
     "--residual-p-rule: 1.0 must be in (0, 1)"),
    ("ppo_grid.py", ["--env-config", '{"reward": {"collison": 1}}', "--out", "out"],
     "config.reward.collison: unknown key"),
    ("ppo_grid.py", ["--total-timesteps", "-5", "--out", "out"],
     "--total-timesteps -5: must be at least 1"),
    ("ppo_grid.py", ["--n-envs", "0", "--out", "out"], "--n-envs 0: must be at least 1"),
    # refused before any env is built (they trained nonsense, or crashed after a rollout)
    ("ppo_grid.py", ["--gamma", "1.5", "--out", "out"], "--gamma 1.5: must be in [0.0, 1.0]"),
    ("ppo_grid.py", ["--n-epochs", "0", "--out", "out"], "--n-epochs 0: must be at least 1"),
    ("ppo_grid.py", ["--ent-coef", "nan", "--out", "out"], "--ent-coef nan: must be at least"),
    ("ppo_grid.py", ["--max-episode-steps", "-1", "--out", "out"],
     "--max-episode-steps -1: must be at least 0"),
    ("evaluate.py", ["--env-id", "DSTGrid-Nope-v0", "--policies", "random"],
     "--env-id DSTGrid-Nope-v0: not a registered DSTGrid id"),
    ("evaluate.py", ["--env-id", "CartPole-v1", "--policies", "random"],
     "not a registered DSTGrid id"),
    ("evaluate.py", ["--max-episode-steps", "-3", "--policies", "random"],
     "--max-episode-steps -3: must be at least 0"),
    ("evaluate.py", ["--csv", ".", "--policies", "random"], "--csv .: is a directory"),
    ("evaluate.py", ["--policies", "random", "--checkpoints", "no-such.pt"],
     "--checkpoints: no such file"),  # before the random driver's episodes
    ("tune_rule.py", ["--out", "."], "--out .: is a directory"),
    ("evaluate.py", ["--policies", "--checkpoints", "no-such.pt"],
     "--checkpoints: no such file"),
    ("rule_based.py", ["--driver", "bogus"], "--driver: expected one of"),
    ("tune_rule.py", ["--grid", '{"x": [1]}', "--out", "out/s.json"],
     "--grid: unknown parameter 'x'"),
    ("compare.py", ["--a", "nope.csv", "--b", "out/b.csv"], "nope.csv: no such file"),
    ("random_policy.py", ["--env-config", "[1]"], "--env-config: expected a JSON object"),
    ("curves.py", ["--runs", "no-such-run", "--out", "c.png"], "no-such-run"),
    ("curves.py", ["--runs", "r", "--out", "c10"], "--out c10: the picture is a PNG"),
    # attack 18: these were accepted
    ("evaluate.py", ["--policies", "--csv", "out/none.csv"],
     "nothing to evaluate: give --policies NAMES and/or --checkpoints FILES"),
    ("evaluate.py", ["--policies", "autopilot", "--shield", "grid"],
     "--shield: no policy to hold back"),
    ("evaluate.py", ["--policies", "random", "--csv", "out/r.json"],
     "--csv out/r.json: the file is CSV; give a name ending in .csv"),
    ("evaluate.py", ["--policies", "random", "--env-config", '{"world": {"map": {"pool": 3}}}'],
     "--env-config world.map.pool: the drivers are scored and tuned on a fresh map per seed"),
    ("ppo_grid.py", ["--env-config", '{"world": {"map": {"pool": 3}}}', "--out", "out"],
     "takes its training maps as --map-pool"),
    ("random_policy.py", ["--csv", "."], "--csv .: is a directory"),  # (after the episodes)
    ("rule_based.py", ["--csv", "out/x.json"], "the file is CSV"),
])
def test_scripts_report_bad_input_in_one_line(tmp_path, script, argv, message) -> None:
    """Each baseline script turns an expected error into one line and exit status 2,
    as ``dstenv`` does; nothing is written."""
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, str(BASELINES / script), *argv], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2, proc.stderr
    assert len(lines) == 1 and lines[0].startswith(f"{script}: error: ")
    assert message in lines[0]
    # not even an empty output folder
    assert not (tmp_path / "out").exists() and not (tmp_path / "c.png").exists()


def test_ppo_grid_refuses_an_out_holding_a_run(tmp_path) -> None:
    """A finished (or interrupted) run in --out is never overwritten in silence."""
    import subprocess
    import sys

    run = tmp_path / "run"
    run.mkdir()
    (run / "episodes.csv").write_text("timesteps\n")
    proc = subprocess.run([sys.executable, str(BASELINES / "ppo_grid.py"), "--out", str(run)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "holds a training run (episodes.csv)" in proc.stderr
    assert (run / "episodes.csv").read_text() == "timesteps\n"



def test_no_output_replaces_a_file_of_a_training_run(tmp_path) -> None:
    """Attack 18: --csv runs/x/model.json replaced the sidecar (the checkpoint was then
    unusable), --csv runs/x/episodes.csv the learning curve."""
    import pytest
    from rl_common import output_file

    run = tmp_path / "run"
    run.mkdir()
    for name in ("model.pt", "model.json", "episodes.csv", "model_64.json"):
        (run / name).write_text("{}" if name.endswith(".json") else "x\n")
    for name in ("model.json", "episodes.csv", "progress.csv", "model_64.json", "model_9.pt"):
        suffix = ".json" if name.endswith(".json") else ".csv"
        with pytest.raises(ValueError, match=rf"--csv .*run/{name}: is a file of the training "
                                             r"run in .*run; give another file name"):
            output_file(str(run / name), "--csv", suffix)
    output_file(str(run / "eval.csv"), "--csv")  # a report of its own beside the run: fine
    output_file(str(tmp_path / "episodes.csv"), "--csv")  # no run there


def test_a_run_folder_is_claimed_by_one_training_at_a_time(tmp_path) -> None:
    """Attack 18: two trainings into one --out both 'succeeded' and one run was lost;
    removing the four run files let a new run overwrite kept checkpoints."""
    import pytest
    from runfolder import claim

    from dstenv.data.lock import DatasetLocked

    with claim(tmp_path / "r") as out:
        with pytest.raises(DatasetLocked, match=r"another run holds it \(its lock .*\.dstenv"
                                                r"\.lock\); wait for it, use another --out, "
                                                r"or delete that lock file"):
            with claim(out):
                pass
        (out / "model_64.pt").write_bytes(b"x")
    with pytest.raises(ValueError, match=r"holds a training run \(model_64\.pt\)"):
        with claim(tmp_path / "r"):
            pass
    with pytest.raises(RuntimeError):  # a run that fails before writing leaves no folder
        with claim(tmp_path / "s"):
            raise RuntimeError("boom")
    assert not (tmp_path / "s").exists()
