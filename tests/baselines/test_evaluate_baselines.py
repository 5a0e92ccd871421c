"""The evaluation script: fixed seeds, loading a checkpoint, the README block."""

from __future__ import annotations

import evaluate
import numpy as np
import ppo_grid
from evaluate import BEGIN, END, write_readme


def test_write_readme_replaces_only_the_block(tmp_path) -> None:
    readme = tmp_path / "README.md"
    readme.write_text(f"# Title\n\nintro\n\n{BEGIN}\nold table\n{END}\n\n## After\n")
    write_readme(readme, "new table\n")
    assert readme.read_text() == f"# Title\n\nintro\n\n{BEGIN}\nnew table\n{END}\n\n## After\n"
    fresh = tmp_path / "fresh.md"
    write_readme(fresh, "t\n")
    write_readme(fresh, "u\n")
    assert fresh.read_text().count(BEGIN) == 1 and "u\n" in fresh.read_text()
    # a file without the markers is never appended to (a .py got a Markdown table once)
    import pytest

    code = tmp_path / "notes.py"
    code.write_text("x = 1\n")
    with pytest.raises(ValueError, match="has no results block"):
        write_readme(code, "t\n")
    assert code.read_text() == "x = 1\n"


def test_saved_model_loads_and_evaluates(tmp_path, env_flags: list[str]) -> None:
    out = tmp_path / "ppo"
    ppo_grid.main([*env_flags, "--n-envs", "1", "--vec-env", "dummy", "--n-steps", "32",
                   "--batch-size", "32", "--n-epochs", "1", "--total-timesteps", "32",
                   "--map-pool", "2", "--verbose", "0", "--out", str(out)])
    readme, csv = tmp_path / "README.md", tmp_path / "episodes.csv"
    readme.write_text(f"# kept\n\n{BEGIN}\n{END}\n")
    argv = [*env_flags, "--policies", "random", "autopilot", "--episodes", "2",
            "--checkpoints", str(out / "model.pt"), "--readme", str(readme), "--csv", str(csv)]
    block = evaluate.main(argv)
    assert readme.read_text() == f"# kept\n\n{BEGIN}\n{END}\n"  # only with --write-readme
    table = [line for line in block.splitlines() if line.startswith("| ")]
    assert [row.split(" | ")[0] for row in table[1:]] == [
        "| random", "| autopilot (privileged)", "| PPO grid-cnn (ppo)"]
    assert "32 steps" in table[-1]  # the training budget from model.json
    assert "python baselines/evaluate.py" in block and "--episodes 2" in block
    lines = csv.read_text().splitlines()
    assert len(lines) == 1 + 3 * 2
    seeds = [line.split(",")[1] for line in lines[1:]]
    assert seeds == ["10000", "10001"] * 3  # the same seeds for every policy
    # evaluating again gives the same numbers, and --write-readme writes the block
    again = evaluate.main([*argv, "--write-readme"])
    strip = lambda b: [ln for ln in b.splitlines() if ln.startswith("| ")]  # noqa: E731
    assert strip(again) == strip(block)
    assert again in readme.read_text() and readme.read_text().startswith("# kept")


def test_bad_arguments_and_files_are_one_line(tmp_path, env_flags: list[str]) -> None:
    import pytest

    for extra, message in ((["--torch-threads", "0"], "--torch-threads must be >= 1"),
                           (["--seed", "-5"], "--episodes must be >= 1 and the seeds"),
                           (["--episodes", "0"], "--episodes must be >= 1")):
        with pytest.raises(ValueError, match=message):  # one line via rl_common.cli
            evaluate.main([*env_flags, "--policies", "random", "--episodes", "1", *extra])
    import json
    from pathlib import Path

    repo = Path(__file__).resolve().parents[2]
    meta = json.loads((repo / "baselines/checkpoints/ppo_occluded_route_s0_450k.json").read_text())
    for key in ("observation_space", "action_space"):  # as if trained on this small env
        meta.pop(key)
    for name, data in (("empty.pt", b""), ("text.pt", b"not a checkpoint\n")):
        (tmp_path / name).write_bytes(data)
        (tmp_path / name.replace(".pt", ".json")).write_text(json.dumps(meta))
        with pytest.raises(ValueError, match=rf"{name}: not a readable policy checkpoint"):
            evaluate.main([*env_flags, "--policies", "--episodes", "1", "--checkpoints",
                           str(tmp_path / name)])
    # names and weights are checked before the first episode of any policy (a bad one
    # used to fail after the others had run, their results lost)
    ran: list[str] = []
    real = evaluate.evaluate_policy
    evaluate.evaluate_policy = lambda env, policy, *a, **k: ran.append(policy.name) or real(
        env, policy, *a, **k)
    try:
        with pytest.raises(ValueError, match="text.pt: not a readable policy checkpoint"):
            evaluate.main([*env_flags, "--policies", "random", "--episodes", "1",
                           "--checkpoints", str(tmp_path / "text.pt")])
        with pytest.raises(ValueError, match="unknown policy 'bogus'"):
            evaluate.main([*env_flags, "--policies", "random", "bogus", "--episodes", "1"])
    finally:
        evaluate.evaluate_policy = real
    assert ran == []


def test_temperature_sampling_is_seeded_and_sharpens(tmp_path, env_flags: list[str]) -> None:
    import numpy as np
    import pytest
    from rl_common import parse_args

    out = tmp_path / "ppo"
    ppo_grid.main([*env_flags, "--n-envs", "1", "--vec-env", "dummy", "--n-steps", "32",
                   "--batch-size", "32", "--n-epochs", "1", "--total-timesteps", "32",
                   "--map-pool", "2", "--verbose", "0", "--out", str(out)])
    args = parse_args(evaluate.Args, env_flags)
    hot = evaluate.PPOPolicy(out / "model.pt", temperature=1.0)
    cold = evaluate.PPOPolicy(out / "model.pt", temperature=0.05)
    env = hot.make_env(args)
    cold.model = hot.model
    obs, _ = env.reset(seed=3)
    p1, p_cold = hot.probabilities(obs), cold.probabilities(obs)
    # T = 1 is the policy's own distribution; small T concentrates it on the argmax
    import torch
    with torch.no_grad():
        tensor, _ = hot.model.policy.obs_to_tensor(obs)
        own = hot.model.policy.get_distribution(tensor).distribution.probs[0].numpy()
    assert p1.shape == (env.action_space.n,) and np.isclose(p1.sum(), 1.0)
    np.testing.assert_allclose(p1, own, rtol=1e-5, atol=1e-7)
    assert np.argmax(p_cold) == np.argmax(p1) and p_cold.max() >= p1.max()
    # the same seed gives the same sampled actions
    picks = []
    for _ in range(2):
        hot.reset(env, 7)
        picks.append([hot.act(obs, {}) for _ in range(20)])
    assert picks[0] == picks[1]
    env.close()
    assert hot.name.endswith("T=1")
    with pytest.raises(ValueError, match="--temperature"):
        evaluate.PPOPolicy(out / "model.pt", temperature=-1.0)


def test_shield_takes_the_slower_action_and_adds_a_row(tmp_path, env_flags: list[str]) -> None:
    import pytest
    from rl_common import parse_args
    from rule_based import grid_driver, shielded

    out = tmp_path / "ppo"
    ppo_grid.main([*env_flags, "--n-envs", "1", "--vec-env", "dummy", "--n-steps", "32",
                   "--batch-size", "32", "--n-epochs", "1", "--total-timesteps", "32",
                   "--map-pool", "2", "--verbose", "0", "--out", str(out)])
    ppo = evaluate.PPOPolicy(out / "model.pt", temperature=1.0)  # sampled: actions vary
    env = ppo.make_env(parse_args(evaluate.Args, env_flags))
    policy, tuned = shielded(ppo, "grid-tuned"), grid_driver(True)
    obs, info = env.reset(seed=5)
    policy.reset(env, 5)
    tuned.reset(env, 5)
    picked = []
    for _ in range(30):
        ppo.rng = np.random.default_rng(len(picked))  # the same draw for both calls
        mine = ppo.act(obs, info)
        ppo.rng = np.random.default_rng(len(picked))
        action, rule = policy.act(obs, info), tuned.act(obs, info)
        assert action == min(mine, rule)
        picked.append((action, mine, rule))
        obs, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            break
    assert len({m for _, m, _ in picked}) > 1  # the check saw more than one PPO action
    env.close()
    assert policy.name == ppo.name + " + shield grid-tuned"
    block = evaluate.main([*env_flags, "--policies", "grid-tuned", "--episodes", "1",
                           "--checkpoints", str(out / "model.pt"), "--shield", "grid"])
    rows = [ln.split(" | ")[0] for ln in block.splitlines() if ln.startswith("| ")][1:]
    assert rows == ["| rule-based (grid, tuned)", "| PPO grid-cnn (ppo)",
                    "| rule-based (grid, tuned) + shield grid",
                    "| PPO grid-cnn (ppo) + shield grid"]
    with pytest.raises(ValueError, match="--shield: expected one of"):
        evaluate.main([*env_flags, "--policies", "--episodes", "1", "--checkpoints",
                       str(out / "model.pt"), "--shield", "nope"])


def test_budget_counts_a_warm_starts_steps():
    from evaluate import _budget

    plain = {"timesteps": 450_048, "wall_time_s": 3300.0}
    assert _budget(plain) == "450,048 steps, 55 min"
    warm = {"timesteps": 0, "env_steps": 100_000, "wall_time_s": 894.3,
            "warm_start": {"timesteps": 100_000}}
    assert _budget(warm) == "100,000 steps (100,000 of them imitation), 15 min"
    assert _budget(None) == "-"


def test_an_imitation_checkpoint_is_named_for_its_learner():
    from pathlib import Path

    from evaluate import PPOPolicy

    root = Path(__file__).resolve().parents[2] / "baselines" / "checkpoints"
    warm = PPOPolicy(root / "dagger_occluded_route_s0_100k.pt")  # saved before PPO's first step
    assert warm.name == "DAgger route-cnn (dagger_occluded_route_s0_100k)"
    assert PPOPolicy(root / "ppo_occluded_route_s0_450k.pt").name.startswith("PPO route-cnn")


def test_default_policies_that_cannot_drive_the_env_are_left_out_with_a_note(capsys) -> None:
    import json

    import pytest
    from conftest import SMALL_CONFIG

    flags = ["--env-id", "DSTGrid-Continuous-v0", "--env-config", json.dumps(SMALL_CONFIG),
             "--max-episode-steps", "5", "--episodes", "1"]
    block = evaluate.main(flags)  # the defaults: random, grid, autopilot, constant
    out = capsys.readouterr().out
    assert "note: default policy grid left out on this env" in out
    assert "note: default policy constant left out on this env" in out
    assert "| random |" in block and "autopilot" in block and "rule-based" not in block
    with pytest.raises(ValueError, match="not action.type 'continuous'"):  # named: refused
        evaluate.main([*flags, "--policies", "grid"])


def test_checkpoints_are_told_apart_and_a_sidecar_must_be_whole(tmp_path) -> None:
    """Attack 18: two checkpoints named alike were one row (and one curves.py line); the
    same file twice ran twice; a sidecar without 'wall_time_s' failed after the episodes."""
    import json
    import shutil
    from pathlib import Path

    import pytest

    repo = Path(__file__).resolve().parents[2] / "baselines" / "checkpoints"
    src = repo / "dagger_occluded_route_s0_100k"
    paths = []
    for top in ("x", "y"):
        (tmp_path / top / "s0").mkdir(parents=True)
        for ext in (".pt", ".json"):
            shutil.copyfile(src.with_suffix(ext), tmp_path / top / "s0" / f"model{ext}")
        paths.append(tmp_path / top / "s0" / "model.pt")
    policies = [evaluate.PPOPolicy(p) for p in paths]
    evaluate._unique_names(policies)
    assert [p.name for p in policies] == [f"DAgger route-cnn (s0) [{p}]" for p in paths]
    with pytest.raises(ValueError, match=r"--checkpoints: .*x/s0/\.\./s0/model\.pt is given "
                                         r"twice"):
        evaluate.main(["--policies", "--checkpoints", str(paths[0]),
                       str(tmp_path / "x/s0/../s0/model.pt")])
    meta = json.loads((tmp_path / "x/s0/model.json").read_text())
    del meta["wall_time_s"]
    (tmp_path / "x/s0/model.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match=r"model\.json: not the model\.json of a ppo_grid\.py "
                                         r"run \(bad JSON, or no 'wall_time_s'\)"):
        evaluate.PPOPolicy(paths[0])
