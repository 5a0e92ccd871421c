"""Every number of the DST update, in one dataclass (``dst-spec.md``)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any

__all__ = ["DSTParams", "SECTION"]


@dataclass(frozen=True)
class DSTParams:
    """Parameters of the perception-grid update.

    Attributes:
        sensor_confidence: c_s, mass a LIDAR observation puts on F or O.
        map_confidence: c_m, mass the map puts on its refined class.
        alpha: discount rate of the past grid (information ageing); 0 keeps all.
        delta_inc: accumulator increment while a cell stays occupied without conflict.
        delta_dec: accumulator decrement on conflict.
        gamma_occupied: gamma_O, occupied mass of the past grid needed to increment.
        gamma_conflict: gamma_conf, conflict (c_FO + c_OF) above which zeta decreases.
    """

    sensor_confidence: float = 0.8
    map_confidence: float = 0.995
    alpha: float = 0.1
    delta_inc: float = 2.0 / 3.0
    delta_dec: float = 2.0 / 3.0
    gamma_occupied: float = 0.6
    gamma_conflict: float = 0.6

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not isinstance(value, (int, float)) or not 0.0 <= float(value) <= 1.0:
                raise ValueError(f"DSTParams.{f.name} must be a number in [0, 1], got {value!r}")

    @classmethod
    def default(cls) -> "DSTParams":
        """The spec's defaults (alpha = 0.1: keep 90% of the past)."""
        return cls()

    @classmethod
    def paper(cls) -> "DSTParams":
        """The paper's literal values (alpha = 0.9: keep only 10% of the past)."""
        return cls(alpha=0.9)

    @classmethod
    def preset(cls, name: str) -> "DSTParams":
        """A named preset: ``"default"`` or ``"paper"``."""
        presets = {"default": cls.default, "paper": cls.paper}
        if name not in presets:
            raise ValueError(f"unknown DST preset {name!r}; choose from {', '.join(presets)}")
        return presets[name]()

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> "DSTParams":
        """Build from a config section; unknown keys raise naming the allowed ones."""
        allowed = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - allowed)
        if unknown:
            raise ValueError(
                f"unknown DST parameter {unknown[0]!r}; allowed: {', '.join(sorted(allowed))}"
            )
        out = {}
        for k, v in values.items():
            try:
                if isinstance(v, bool):
                    raise TypeError
                out[k] = float(v)
            except (TypeError, ValueError):
                raise ValueError(f"DST parameter {k}: {v!r} is not a number") from None
        return cls(**out)

    def to_dict(self) -> dict[str, float]:
        """Plain dict of every field (JSON-serialisable)."""
        return {k: float(v) for k, v in asdict(self).items()}


def _section() -> Any:
    from dstenv.config import PROB, Section

    return Section(lambda: DSTParams.default().to_dict(),
                   {f.name: PROB for f in fields(DSTParams)})


#: The ``dst`` section of the configuration (:func:`dstenv.config.build_config`).
SECTION = _section()
