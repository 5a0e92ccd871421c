"""Scenario files: TOML overrides of the default configuration, shipped or the user's.

Shipped scenarios live in the top-level ``scenarios/`` directory (installed as the
``dstenv.scenarios`` package). A file holds an optional ``description`` string and
sections that override the default configuration; :func:`load_scenario` merges it
with :func:`dstenv.config.merge_config`, so unknown keys are rejected by name, and
:func:`dstenv.config.build_config` validates the result.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Mapping
from importlib import resources
from pathlib import Path
from typing import Any

from dstenv.config import ConfigError, merge_config

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = ["list_scenarios", "load_scenario", "scenario_path"]

#: top-level keys of a scenario file that are not configuration sections
_SCENARIO_META_KEYS = ("description",)


def _scenario_dir() -> Path:
    return Path(str(resources.files("dstenv.scenarios")))


def list_scenarios() -> list[str]:
    """Names of the scenario files shipped with dstenv (``scenarios/*.toml``)."""
    return sorted(p.stem for p in _scenario_dir().glob("*.toml"))


def scenario_path(name_or_path: str | Path) -> Path:
    """Resolve a scenario name (``"dense"``) or a path to a ``.toml`` file.

    A bare name (no ``.toml`` suffix, no folder) always means a shipped scenario,
    so a file or folder called ``dense`` in the working directory never shadows it;
    write ``./dense.toml`` (or any path with a folder or the suffix) for a file.

    Raises:
        ConfigError: if no such scenario exists (listing the known names).
    """
    if not isinstance(name_or_path, (str, os.PathLike)):
        raise ConfigError(f"scenario: a shipped name or a .toml path, got "
                          f"{type(name_or_path).__name__} {name_or_path!r}")
    text = str(name_or_path)
    candidate = Path(name_or_path)
    if candidate.suffix == ".toml" or "/" in text or (os.sep != "/" and os.sep in text):
        if not candidate.is_file():
            what = "is a folder, not a" if candidate.is_dir() else "not found: no such"
            raise ConfigError(f"scenario {candidate}: {what} file; give an existing "
                              f".toml file or a shipped name ({', '.join(list_scenarios())})")
        return candidate
    path = _scenario_dir() / f"{text}.toml"
    if not path.is_file():
        known = ", ".join(list_scenarios())
        raise ConfigError(f"unknown scenario {text!r}; known scenarios: {known} "
                          "(a file needs its .toml suffix or a folder, e.g. "
                          f"./{text if text.strip('.') else 'my_scenario'}.toml)")
    return path


def _resolve_osm_file(raw: dict[str, Any], path: Path) -> None:
    """A user's scenario names its OSM map relative to its own folder (module doc)."""
    m = raw.get("world", {}).get("map", {}) if isinstance(raw.get("world"), dict) else {}
    osm = m.get("osm_file") if isinstance(m, dict) else None
    if not isinstance(osm, str) or not osm or Path(osm).is_absolute():
        return
    if path.resolve().parent == _scenario_dir().resolve():
        return  # shipped: stays relative, the same config on every install
    beside = path.resolve().parent / osm
    if beside.is_file():
        m["osm_file"] = str(beside)


def load_scenario(
    name_or_path: str | Path, defaults: Mapping[str, Any] | None = None
) -> dict[str, Any]:
    """Read a scenario file and merge it into ``defaults``.

    Args:
        name_or_path: a shipped scenario name or a path to a TOML file.
        defaults: the full default configuration to override; when ``None`` the raw
            (validated-as-TOML) overrides are returned without the meta keys.

    Returns:
        The merged configuration. A relative ``world.map.osm_file`` of a user's file
        that exists beside it becomes that absolute path (whatever the current folder);
        otherwise relative paths stay as written (the shipped scenarios' maps are found
        by :class:`dstenv.sim.world.World`).

    Raises:
        ConfigError: unreadable file, invalid TOML (with line), or unknown keys.
    """
    path = scenario_path(name_or_path)
    try:
        with path.open("rb") as fh:
            raw = tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: invalid TOML: {exc}") from None
    except RecursionError:
        raise ConfigError(f"{path}: invalid TOML: nested too deeply") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror}") from None
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: not UTF-8 text at byte {exc.start} (TOML files are UTF-8); "
                          "save it as UTF-8") from None
    _resolve_osm_file(raw, path)
    overrides = {k: v for k, v in raw.items() if k not in _SCENARIO_META_KEYS}
    if "description" in raw and not isinstance(raw["description"], str):
        raise ConfigError(f"{path}: 'description' must be a string")
    if defaults is None:
        return overrides
    return merge_config(defaults, overrides, where=str(path))
