"""Plain-data configuration: the one gate that merges and validates it, and scenario files.

Every subsystem owns a ``default_config()`` returning a nested ``dict`` (units in
comments, HighwayEnv style) and a :class:`Section` that pairs it with a table of
:class:`Rule` (type, finite range, choices) per key plus cross-key checks. User
overrides and scenario files are merged with :func:`merge_config`, which rejects
unknown keys by name and lists the allowed ones, so a typo never silently falls
back to a default.

:func:`build_config` is the gate: it merges a scenario and overrides once and
validates every section eagerly, so a bad value is rejected at construction with
a message that names the key and the allowed range. It returns a
:class:`Validated` dict (and validated sections), which constructors take as is
instead of merging again; :func:`section` validates one section for direct use of
a lower layer (``World({"traffic": {"cars": 3}})``).

Scenario files (TOML overrides, shipped in ``scenarios/`` or the user's) are read by
:mod:`dstenv.scenario_files`.
"""

from __future__ import annotations

import copy
import importlib
import math
import numbers
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = [
    "leaf_diffs",
    "CLIError",
    "ConfigError",
    "Rule",
    "Section",
    "SECTIONS",
    "Validated",
    "build_config",
    "section",
    "validate_config",
    "between",
    "at_least",
    "one_of",
    "PROB",
    "merge_config",
]


class ConfigError(ValueError):
    """A configuration or scenario file is invalid; the message names the problem."""


def leaf_diffs(old: Any, new: Any, at: str = "") -> list[tuple[str, Any, Any]]:
    """``(dotted key, old, new)`` of every setting that differs (tables compared key by
    key, so a message names ``config.stride``, not two whole configurations)."""
    if isinstance(old, dict) and isinstance(new, dict):
        return [d for k in sorted(set(old) | set(new))
                for d in leaf_diffs(old.get(k), new.get(k), f"{at}.{k}" if at else str(k))]
    return [] if old == new else [(at, old, new)]


class CLIError(Exception):
    """A user-facing error of the ``dstenv`` command: printed as one line, exit status 2."""


# --------------------------------------------------------------------------- rules
@dataclass(frozen=True)
class Rule:
    """What values one key accepts: a closed/open numeric range or a set of choices.

    Numbers are always required to be finite; ``lo``/``hi`` are inclusive unless
    ``lo_open``/``hi_open``. Every numeric key should have a sane upper bound, so
    that a typo (``1e9`` cars) is an error rather than an hour of work or an
    out-of-memory kill.
    """

    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    choices: tuple[Any, ...] | None = None
    unit: str = ""
    what: str = "value"  # what a choice is, for messages ("scene")

    def describe(self) -> str:
        """The allowed values, for error messages (``"in (0, 360] deg"``)."""
        if self.choices is not None:
            return "one of " + ", ".join(repr(c) for c in self.choices)
        unit = f" {self.unit}" if self.unit else ""
        if self.hi is None:
            return f"{'>' if self.lo_open else '>='} {self.lo:g}{unit}"
        if self.lo is None:
            return f"{'<' if self.hi_open else '<='} {self.hi:g}{unit}"
        left, right = "(" if self.lo_open else "[", ")" if self.hi_open else "]"
        return f"in {left}{self.lo:g}, {self.hi:g}{right}{unit}"

    def check(self, value: Any, path: str) -> None:
        """Raise :class:`ConfigError` naming ``path`` unless ``value`` is allowed."""
        if self.choices is not None:
            if value not in self.choices:
                raise ConfigError(f"{path}: unknown {self.what} {value!r}; allowed: "
                                  + ", ".join(str(c) for c in self.choices))
            return
        values = value if isinstance(value, (list, tuple)) else [value]
        for v in values:
            ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
            if ok and self.lo is not None:
                ok = v > self.lo if self.lo_open else v >= self.lo
            if ok and self.hi is not None:
                ok = v < self.hi if self.hi_open else v <= self.hi
            if not ok:
                raise ConfigError(f"{path}: must be {self.describe()}, got {value!r}")


def between(lo: float, hi: float, unit: str = "", *, lo_open: bool = False,
            hi_open: bool = False) -> Rule:
    """A number in ``[lo, hi]`` (open ends on request)."""
    return Rule(lo, hi, lo_open, hi_open, unit=unit)


def at_least(lo: float, hi: float, unit: str = "", *, lo_open: bool = False) -> Rule:
    """A number ``>= lo`` (``> lo`` with ``lo_open``) and at most the sanity bound ``hi``."""
    return Rule(lo, hi, lo_open, unit=unit)


def one_of(*choices: Any, what: str = "value") -> Rule:
    """One of the listed values (``what`` names a choice in messages)."""
    return Rule(choices=tuple(choices), what=what)


#: A probability.
PROB = between(0.0, 1.0)

#: A cross-key check: ``(key, predicate(section) -> ok, what it must be)``.
Check = tuple[str, Callable[[Mapping[str, Any]], bool], str]


@dataclass(frozen=True)
class Section:
    """A configuration section: its defaults, a rule table and cross-key checks.

    Attributes:
        defaults: returns the complete default section (a new dict per call).
        rules: nested like the defaults; a leaf is a :class:`Rule`.
        checks: cross-key checks, run after every rule passed.
    """

    defaults: Callable[[], dict[str, Any]]
    rules: Mapping[str, Any]
    checks: Sequence[Check] = ()

    def validate(self, cfg: Mapping[str, Any], where: str) -> None:
        """Raise :class:`ConfigError` on the first bad value of ``cfg``."""
        _check_rules(cfg, self.rules, where)
        for key, ok, why in self.checks:
            if not ok(cfg):
                raise ConfigError(f"{_join(where, key)}: {why}")


def _join(where: str, key: str) -> str:
    return f"{where}.{key}" if where else key


def _check_rules(cfg: Mapping[str, Any], rules: Mapping[str, Any], where: str) -> None:
    for key, value in cfg.items():
        path = _join(where, key)
        rule = rules.get(key)
        if isinstance(value, Mapping):
            _check_rules(value, rule if isinstance(rule, Mapping) else {}, path)
        elif isinstance(rule, Rule):
            rule.check(value, path)
        else:
            _check_finite(value, path)


def _check_finite(value: Any, path: str) -> None:
    """Numbers without a rule must still be finite (NaN and inf are never a setting)."""
    values = value if isinstance(value, (list, tuple)) else [value]
    for v in values:
        if isinstance(v, float) and not math.isfinite(v):
            raise ConfigError(f"{path}: must be a finite number, got {value!r}")


#: section name -> ``"module:attribute"`` of its :class:`Section`, imported only when
#: that section is validated (so validating the core never imports gymnasium).
SECTIONS: dict[str, str] = {
    "source": "dstenv.pipeline:SOURCE_SECTION",
    "world": "dstenv.sim.config:SECTION",
    "highway": "dstenv.sim.highway:SECTION",
    "lidar": "dstenv.sensing.config:LIDAR",
    "gis": "dstenv.sensing.config:GIS",
    "labels": "dstenv.sensing.config:LABELS",
    "grid": "dstenv.grid:SECTION",
    "dst": "dstenv.dst.params:SECTION",
    "protocol": "dstenv.pipeline:PROTOCOL_SECTION",
    "frame": "dstenv.pipeline:FRAME_SECTION",
    "observation": "dstenv.envs.observation:SECTION",
    "action": "dstenv.envs.actions:SECTION",
    "reward": "dstenv.envs.rewards:SECTION",
    "info": "dstenv.envs.info:INFO_SECTION",
}


def _section_spec(name: str) -> Section:
    try:
        module, attr = SECTIONS[name].split(":")
    except KeyError:
        known = ", ".join(SECTIONS)
        raise ConfigError(f"unknown config section {name!r}; known: {known}") from None
    return getattr(importlib.import_module(module), attr)


class Validated(dict):
    """A configuration or section that passed :func:`build_config` / :func:`section`.

    Constructors take it as is; a plain dict is merged and validated first.
    """


def _mark(cfg: Mapping[str, Any]) -> Validated:
    return Validated({k: _mark(v) if isinstance(v, dict) and k in SECTIONS else v
                      for k, v in cfg.items()})


def section(name: str, overrides: Mapping[str, Any] | None = None,
            where: str | None = None) -> Validated:
    """One validated section: ``overrides`` merged over its defaults and checked.

    A :class:`Validated` section is returned unchanged (no second merge).

    Raises:
        ConfigError: unknown key, wrong type, or a value outside its rule (named).
    """
    if isinstance(overrides, Validated):
        return overrides
    where = where or name
    spec = _section_spec(name)
    cfg = merge_config(spec.defaults(), overrides, where)
    spec.validate(cfg, where)
    return Validated(cfg)


def validate_config(cfg: Mapping[str, Any], where: str = "config") -> Validated:
    """Validate every section of a full configuration eagerly.

    Sections named in :data:`SECTIONS` are checked against their rule tables; any
    other key must hold finite numbers. Returns the configuration marked
    :class:`Validated`.
    """
    for name, value in cfg.items():
        path = _join(where, name)
        if name in SECTIONS:
            spec = _section_spec(name)
            if isinstance(value, Mapping):
                spec.validate(value, path)
            else:  # a top-level scalar such as ``source``
                spec.validate({name: value}, where)
        elif isinstance(value, Mapping):
            _check_rules(value, {}, path)
        else:
            _check_finite(value, path)
    return _mark(cfg)


Override = Mapping[str, Any] | tuple[str, Mapping[str, Any] | None] | None


def build_config(scenario: str | Path | None = None, *overrides: Override,
                 defaults: Mapping[str, Any] | None = None) -> Validated:
    """The configuration gate: defaults <- scenario file <- overrides, validated once.

    Args:
        scenario: a shipped scenario name or a ``.toml`` path; ``None`` for none.
        *overrides: partial configurations merged in order; each is a mapping or
            ``(name, mapping)`` where ``name`` labels it in error messages.
        defaults: the complete defaults; :func:`dstenv.pipeline.default_config` when
            ``None`` (the environment passes its own, with its extra sections).

    Returns:
        The full configuration, every section validated (:class:`Validated`).

    Raises:
        ConfigError: naming the file or key and the allowed values.
    """
    if defaults is None:
        from dstenv.pipeline import default_config

        defaults = default_config()
    if scenario is not None:
        from dstenv.scenario_files import load_scenario

        cfg = load_scenario(scenario, defaults)
    else:
        cfg = dict(defaults)
    layers = []
    for i, item in enumerate(overrides):
        name, value = item if isinstance(item, tuple) else ("config" if i == 0 else
                                                             f"override {i + 1}", item)
        cfg = merge_config(cfg, value, name)
        layers.append((name, value))
    try:
        return validate_config(cfg, "")
    except ConfigError as exc:  # a bad value: name where it was written, when not a default
        key = str(exc).split(":", 1)[0].split(".")
        if scenario is not None:
            from dstenv.scenario_files import load_scenario, scenario_path

            layers.insert(0, (str(scenario_path(scenario)), load_scenario(scenario)))
        for name, value in reversed(layers):
            node: Any = value
            for part in key:
                node = node.get(part) if isinstance(node, Mapping) else None
            if node is not None:
                raise ConfigError(f"{name}: {exc}") from None
        raise


def merge_config(
    defaults: Mapping[str, Any], overrides: Mapping[str, Any] | None, where: str = "config",
    *, nested: bool = False,
) -> dict[str, Any]:
    """Deep-merge ``overrides`` into a copy of ``defaults``, validating keys and types.

    Args:
        defaults: the complete default configuration (nested dicts).
        overrides: a partial configuration; every key must exist in ``defaults``.
        where: name of the source for error messages: a section (``config``: keys
            read ``config.grid.height``), a file or a flag (``--set: grid.height``).
        nested: ``where`` is already a key path (the recursion into sections).

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
    sep = ": " if not nested and (where.startswith("-") or where.endswith(".toml")) else "."
    for key, value in overrides.items():
        path = f"{where}{sep}{key}"
        if key not in out:
            allowed = ", ".join(sorted(out)) or "(none)"
            raise ConfigError(f"{path}: unknown key {key!r}; allowed keys: {allowed}")
        default = out[key]
        if isinstance(default, Mapping) and default:
            if not isinstance(value, Mapping):
                raise ConfigError(f"{path}: expected a table, got {value!r}")
            out[key] = merge_config(default, value, path, nested=True)
        else:
            out[key] = _check_type(default, value, path)
    return out


def _check_type(default: Any, value: Any, path: str) -> Any:
    if isinstance(default, Mapping):  # a free-form table ({} by default): any keys
        if not isinstance(value, Mapping):
            raise ConfigError(f"{path}: expected a table (a TOML inline table, a JSON "
                              f"object, or one setting per key below it), got {value!r}")
        return copy.deepcopy(value)
    if default is None:
        return copy.deepcopy(value)
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise ConfigError(f"{path}: expected true/false, got {value!r}")
        return value
    if isinstance(default, (int, float)):
        if isinstance(value, numbers.Integral) and not isinstance(value, int):
            value = int(value)  # np.int64(84) is a number too
        elif isinstance(value, numbers.Real) and not isinstance(value, (int, float)):
            value = float(value)
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
