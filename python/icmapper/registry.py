"""Name -> item registries of the project's plug-in points (mapping methods, prediction formats,
source kinds, geo frames): one owner of adding an item, refusing a name twice and naming the
known ones when a name is unknown. Each registry stays in the module that owns its kind; this
module knows none of them. No I/O.
"""

from __future__ import annotations

from typing import Protocol, TypeVar


class Named(Protocol):
    """What a registry holds: anything with a ``name``."""

    @property
    def name(self) -> str: ...


T = TypeVar("T", bound=Named)


class Registry(dict[str, T]):
    """Items by name in registration order (a plain dict to read), refusing a name twice.

    what: the kind of item, for the messages ("method", "prediction format", ...)."""

    def __init__(self, what: str) -> None:
        super().__init__()
        self.what = what

    def register(self, item: T) -> T:
        """Adds ``item`` under its name (ValueError for a name registered twice); returns it."""
        if item.name in self:
            raise ValueError(f"{self.what} {item.name!r} is registered twice")
        self[item.name] = item
        return item

    def lookup(self, name: str) -> T:
        """The item registered as ``name`` (ValueError listing the known names)."""
        if name not in self:
            raise ValueError(f"unknown {self.what} {name!r}; expected one of {', '.join(self)}")
        return self[name]
