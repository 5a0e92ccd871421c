"""A small named registry: the one way dstenv lists things users can extend.

Observation and action modes, segmenters and segmentation networks are each a
:class:`Registry`: a ``dict`` from name to entry, so ``REG["mine"] = entry`` and
iteration work as usual, plus :meth:`Registry.get` whose error names the known
entries and the config key that chose the bad one, and :meth:`Registry.register`
which refuses to replace an entry by accident.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Generic, TypeVar

__all__ = ["Registry"]

T = TypeVar("T")


class Registry(dict[str, T], Generic[T]):
    """Named entries of one kind.

    Args:
        what: what an entry is, for messages (``"observation mode"``).
        key: the configuration key or argument that names an entry
            (``"observation.type"``), for messages; ``""`` when none.
    """

    def __init__(self, what: str, key: str = "", entries: dict[str, T] | None = None) -> None:
        super().__init__(entries or {})
        self.what = what
        self.key = key

    def get(self, name: str) -> T:  # type: ignore[override]
        """The entry called ``name``.

        Raises:
            dstenv.config.ConfigError: unknown name (a ``ValueError``), listing the
                known ones.
        """
        if name not in self:
            from dstenv.config import ConfigError

            where = f"{self.key}: " if self.key else ""
            raise ConfigError(f"{where}unknown {self.what} {name!r}; known: {', '.join(self)}")
        return self[name]

    def register(self, name: str, entry: T, overwrite: bool = False) -> T:
        """Add ``entry`` under ``name``; refuses an existing name unless ``overwrite``."""
        if name in self and not overwrite:
            raise ValueError(f"{self.what} {name!r} is already registered")
        self[name] = entry
        return entry

    def decorator(self, name: str) -> Callable[[T], T]:
        """``@REG.decorator("name")`` registers the decorated object."""
        return lambda entry: self.register(name, entry)
