"""The rule driver's parameter search (tune_rule.py) and the tuned driver."""

from __future__ import annotations

import json

import pytest

import rule_based
import tune_rule
from conftest import BASELINES
from rule_based import TUNED_PARAMS, GridRuleDriver

SEARCH = BASELINES.parent / "benchmarks" / "search"


def test_grid_is_the_cartesian_product_in_key_order() -> None:
    configs = tune_rule.parse_grid('{"junction_range": [20, 30], "margin": [4, 6.5]}')
    assert configs == [{"junction_range": 20.0, "margin": 4.0},
                       {"junction_range": 20.0, "margin": 6.5},
                       {"junction_range": 30.0, "margin": 4.0},
                       {"junction_range": 30.0, "margin": 6.5}]
    # a list of objects: those configurations, {} = the defaults
    assert tune_rule.parse_grid('[{}, {"margin": 6}]') == [{}, {"margin": 6.0}]
    assert set(tune_rule.parameter_names()) >= {"junction_range", "margin", "corridor"}
    # the give-way rule on and off (true / false: it was listed but could not be tuned)
    assert tune_rule.parse_grid('{"give_way": [false, true]}') == [{"give_way": False},
                                                                  {"give_way": True}]


@pytest.mark.parametrize("text, message", [
    ("", "expected a JSON object"),
    ("[1, 2]", "expected a JSON object"),
    ("{", "not valid JSON"),
    ('{"junction_rang": [20]}', "unknown parameter 'junction_rang'"),
    ('{"margin": []}', "margin needs a non-empty list"),
    ('{"margin": [4, -1]}', "finite numbers > 0"),
    ('{"margin": [true]}', "finite numbers > 0"),
    ('{"margin": 4}', "non-empty list"),
    ('[{"margin": -4}]', "finite numbers > 0"),
    ('[{"nope": 1}]', "unknown parameter 'nope'"),
    ("[]", "expected a JSON object"),
    ('{"give_way_moving": [7]}', "and <= 1"),  # a BetP threshold
    ('{"give_way": [0, 1]}', "true / false"),
])
def test_bad_grids_are_refused(text: str, message: str) -> None:
    with pytest.raises(ValueError, match="--grid: ") as err:
        tune_rule.parse_grid(text)
    assert message in str(err.value)


def test_best_row_maximises_success_minus_collisions_then_fewer_collisions() -> None:
    def row(success: float, collision: float) -> dict:
        return {"params": {}, "summary": {"success": success, "collision": collision}}

    rows = [row(0.70, 0.10), row(0.80, 0.12), row(0.74, 0.06), row(0.76, 0.08)]
    assert tune_rule.best_row(rows) is rows[2]  # 0.68 twice: the one with fewer collisions
    tie = [row(0.5, 0.1), row(0.5, 0.1)]
    assert tune_rule.best_row(tie) is tie[0]  # then grid order


def test_search_scores_each_configuration_on_the_validation_seeds(tmp_path, env_flags) -> None:
    out = tmp_path / "search.json"
    argv = [*env_flags, "--episodes", "2", "--seed", "20000", "--out", str(out),
            "--grid", '{"junction_range": [20, 40], "corridor": [1.4]}']
    record = tune_rule.main(argv)
    saved = json.loads(out.read_text())
    assert saved["rows"] == record["rows"] and saved["seeds"] == [20000, 20001]
    assert [r["params"] for r in saved["rows"]] == [
        {"junction_range": 20.0, "corridor": 1.4}, {"junction_range": 40.0, "corridor": 1.4}]
    # each row is that driver's own evaluation on the same seeds
    for row in saved["rows"]:
        direct = tune_rule.score(saved["env"], row["params"], [20000, 20001])
        assert row["summary"] == pytest.approx(direct)
        assert row["criterion"] == pytest.approx(direct["success"] - direct["collision"])
    assert saved["best"] == tune_rule.best_row(saved["rows"])
    assert saved["defaults"]["junction_range"] == 20.0


def test_tuned_driver_uses_the_committed_two_stage_search_choice() -> None:
    """Stage 1: the grid on 50 validation seeds; stage 2: the defaults and stage 1's five
    best on 200 more validation seeds; TUNED_PARAMS is stage 2's best."""
    first = json.loads((SEARCH / "rule-driver.json").read_text())
    second = json.loads((SEARCH / "rule-driver-stage2.json").read_text())
    ranked = sorted(first["rows"], key=lambda r: (-r["criterion"], r["summary"]["collision"],
                                                  first["rows"].index(r)))
    assert [r["params"] for r in second["rows"]] == [{}] + [r["params"] for r in ranked[:5]]
    assert first["seeds"] == [20000, 20049] and second["seeds"] == [20050, 20249]
    assert second["best"] == tune_rule.best_row(second["rows"])
    assert TUNED_PARAMS == second["best"]["params"]
    driver, env = rule_based.reference_driver("grid-tuned", rule_based.Args())
    env.close()
    assert isinstance(driver, GridRuleDriver) and driver.name == "rule-based (grid, tuned)"
    for key, value in TUNED_PARAMS.items():
        assert getattr(driver, key) == value
    assert GridRuleDriver.name == "rule-based (grid)"  # the class's name is untouched
