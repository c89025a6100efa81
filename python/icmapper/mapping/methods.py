"""The registry of mapping methods: one ``MethodInfo`` per name of `icmapper map --method` and
`icmapper compare --methods`, in table order.

Two kinds of method:
- a **variant of the learned mapper** (``variant`` set: a key of ``mapper.VARIANTS``), built from a
  checkpoint's networks with ``Mapper.from_checkpoint``;
- a **method on any detection source** (``build`` set): ``build(source, config, rng)`` returns a
  ``MappingMethod`` reading its settings from the shared ``MapperConfig``. Every baseline is one.

A new baseline is one module (the class, with ``name`` set to its registered name) plus one
``register_method`` call at its end, and one line in ``baselines/__init__.py``; the command line's
choices and help come from here. The registry never imports the baselines (each imports the
registry: one import edge); ``icmapper.mapping``'s ``__init__`` imports the ``baselines`` package,
so they are registered whenever anything of ``icmapper.mapping`` is imported.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from icmapper.data.types import PerceptionRange
from icmapper.registry import Registry

if TYPE_CHECKING:
    from icmapper.mapping.config import MapperConfig
    from icmapper.mapping.types import DetectionSource, MappingMethod

#: build(source, config, rng) -> a method reading its settings from ``config``.
MethodBuilder = Callable[["DetectionSource", "MapperConfig", PerceptionRange], "MappingMethod"]


@dataclass(frozen=True)
class MethodInfo:
    """A registered method: its name, one line of help, and how it is built (exactly one of
    ``variant`` and ``build``); ``learned_only``: it needs the learned detector's networks (it
    cannot run on oracle or file detections); ``distinct_without_learned``: without the learned
    detector it differs from every other method (`compare` runs it by default then)."""

    name: str
    help: str
    variant: str | None = None
    build: MethodBuilder | None = None
    learned_only: bool = False
    distinct_without_learned: bool = True

    def __post_init__(self) -> None:
        if (self.variant is None) == (self.build is None):
            raise ValueError(f"method {self.name!r}: give exactly one of variant and build")


_METHODS: Registry[MethodInfo] = Registry("method")


def register_method(info: MethodInfo) -> MethodInfo:
    """Adds a method to the registry (ValueError for a name registered twice)."""
    return _METHODS.register(info)


def methods() -> dict[str, MethodInfo]:
    """Every registered method by name, in table order (the learned mapper's variants first)."""
    return dict(_METHODS)


def method(name: str) -> MethodInfo:
    """The method registered as ``name`` (ValueError listing the known names)."""
    return _METHODS.lookup(name)


def _register_variants() -> None:
    from icmapper.mapping.variants import VARIANTS

    for variant, v in VARIANTS.items():
        name = "icmapper" if variant == "full" else f"icmapper-{variant}"
        # without query features and fusion every variant but "full" repeats another one
        register_method(
            MethodInfo(
                name,
                v.help,
                variant=variant,
                learned_only=v.learned_only,
                distinct_without_learned=variant == "full",
            )
        )


_register_variants()
