"""Plain-data configuration: validated merging and scenario files.

Every subsystem owns a ``default_config()`` returning a nested ``dict`` (units in
comments, HighwayEnv style). User overrides and scenario files are merged into it
with :func:`merge_config`, which rejects unknown keys by name and lists the allowed
ones, so a typo never silently falls back to a default.

Scenario files are TOML files in the top-level ``scenarios/`` directory (installed
as the ``dstenv.scenarios`` package). A scenario file holds an optional
``description`` string and sections that override the default configuration.
"""

from __future__ import annotations

import copy
import sys
from collections.abc import Mapping
from importlib import resources
from pathlib import Path
from typing import Any

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = [
    "ConfigError",
    "merge_config",
    "list_scenarios",
    "scenario_path",
    "load_scenario",
]

_SCENARIO_META_KEYS = ("description",)


class ConfigError(ValueError):
    """A configuration or scenario file is invalid; the message names the problem."""


def merge_config(
    defaults: Mapping[str, Any], overrides: Mapping[str, Any] | None, where: str = "config"
) -> dict[str, Any]:
    """Deep-merge ``overrides`` into a copy of ``defaults``, validating keys and types.

    Args:
        defaults: the complete default configuration (nested dicts).
        overrides: a partial configuration; every key must exist in ``defaults``.
        where: name of the source for error messages (e.g. a file path).

    Returns:
        A new nested dict; ``defaults`` is not modified.

    Raises:
        ConfigError: on an unknown key (naming it and the allowed keys), a section
            given as a scalar, or a value whose type does not match the default.
    """
    out = copy.deepcopy(dict(defaults))
    if overrides is None:
        return out
    if not isinstance(overrides, Mapping):
        raise ConfigError(f"{where}: expected a table of settings, got {type(overrides).__name__}")
    for key, value in overrides.items():
        path = f"{where}.{key}"
        if key not in out:
            allowed = ", ".join(sorted(out)) or "(none)"
            raise ConfigError(f"{path}: unknown key {key!r}; allowed keys: {allowed}")
        default = out[key]
        if isinstance(default, Mapping) and default:
            if not isinstance(value, Mapping):
                raise ConfigError(f"{path}: expected a table, got {value!r}")
            out[key] = merge_config(default, value, path)
        else:
            out[key] = _check_type(default, value, path)
    return out


def _check_type(default: Any, value: Any, path: str) -> Any:
    if default is None or isinstance(default, Mapping):
        return copy.deepcopy(value)
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise ConfigError(f"{path}: expected true/false, got {value!r}")
        return value
    if isinstance(default, (int, float)):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{path}: expected a number, got {value!r}")
        if isinstance(default, int) and not isinstance(default, bool) and isinstance(value, float):
            if not value.is_integer():
                raise ConfigError(f"{path}: expected an integer, got {value!r}")
            return int(value)
        return type(default)(value) if isinstance(default, float) else value
    if isinstance(default, str):
        if not isinstance(value, str):
            raise ConfigError(f"{path}: expected a string, got {value!r}")
        return value
    if isinstance(default, (list, tuple)):
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{path}: expected a list, got {value!r}")
        return type(default)(value)
    return value


def _scenario_dir() -> Path:
    return Path(str(resources.files("dstenv.scenarios")))


def list_scenarios() -> list[str]:
    """Names of the scenario files shipped with dstenv (``scenarios/*.toml``)."""
    return sorted(p.stem for p in _scenario_dir().glob("*.toml"))


def scenario_path(name_or_path: str | Path) -> Path:
    """Resolve a scenario name (``"dense"``) or a path to a ``.toml`` file.

    Raises:
        ConfigError: if no such scenario exists (listing the known names).
    """
    candidate = Path(name_or_path)
    if candidate.suffix == ".toml" or candidate.exists():
        if not candidate.is_file():
            raise ConfigError(f"scenario file not found: {candidate}")
        return candidate
    path = _scenario_dir() / f"{name_or_path}.toml"
    if not path.is_file():
        known = ", ".join(list_scenarios())
        raise ConfigError(f"unknown scenario {str(name_or_path)!r}; known scenarios: {known}")
    return path


def load_scenario(
    name_or_path: str | Path, defaults: Mapping[str, Any] | None = None
) -> dict[str, Any]:
    """Read a scenario file and merge it into ``defaults``.

    Args:
        name_or_path: a shipped scenario name or a path to a TOML file.
        defaults: the full default configuration to override; when ``None`` the raw
            (validated-as-TOML) overrides are returned without the meta keys.

    Returns:
        The merged configuration. Relative paths in the file (e.g. an OSM map)
        stay as written; :func:`scenario_path` gives the directory to resolve them.

    Raises:
        ConfigError: unreadable file, invalid TOML (with line), or unknown keys.
    """
    path = scenario_path(name_or_path)
    try:
        with path.open("rb") as fh:
            raw = tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: invalid TOML: {exc}") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror}") from None
    overrides = {k: v for k, v in raw.items() if k not in _SCENARIO_META_KEYS}
    if "description" in raw and not isinstance(raw["description"], str):
        raise ConfigError(f"{path}: 'description' must be a string")
    if defaults is None:
        return overrides
    return merge_config(defaults, overrides, where=str(path))
