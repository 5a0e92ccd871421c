"""The ``clean`` scenario (today's ideal world) as configs, for tests of exact geometry."""

from __future__ import annotations

from typing import Any

from dstenv.config import merge_config
from dstenv.scenario_files import load_scenario


def clean_world(overrides: dict[str, Any] | None = None) -> dict[str, Any]:
    """The ``world`` section of the clean scenario with ``overrides`` merged on top."""
    from dstenv.sim import default_config

    base = merge_config(default_config(), load_scenario("clean")["world"], "clean")
    return merge_config(base, overrides, "test")


def clean_pipeline(overrides: dict[str, Any] | None = None) -> dict[str, Any]:
    """The full pipeline config of the clean scenario with ``overrides`` merged on top."""
    from dstenv.pipeline import default_config

    return merge_config(load_scenario("clean", default_config()), overrides, "test")
