"""Settings as data: frozen dataclasses built from plain (TOML-shaped) dicts, with checked types.

Every settings class of icmapper (``models.config.ModelConfig``, ``mapping.config.MapperConfig``,
the training config's tables) is a frozen dataclass whose defaults are written once, in the class.
This module turns a table of plain values (a TOML table, a checkpoint's stored config, command-line
``NAME=VALUE`` overrides) into such a class, raising ``ValueError`` that names the key for unknown
keys and values of the wrong type. Range checks belong to each class's ``__post_init__`` or
validator. No I/O here.
"""

from __future__ import annotations

import dataclasses
from dataclasses import fields
from typing import Any, TypeVar

T = TypeVar("T")


#: Element types of the tuple fields whose default is empty, by annotation.
_TUPLE_ELEMENTS: dict[str, type] = {"tuple[int, ...]": int, "tuple[float, ...]": float}


def convert_value(owner: str, f: dataclasses.Field, value: Any) -> Any:
    """Checks one plain value against the type of field ``f`` (known from its default) and
    converts it (ints to floats, lists to tuples). ``owner`` names the table in errors."""
    key = f"{owner}.{f.name}"
    default = f.default if f.default is not dataclasses.MISSING else None
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise ValueError(f"config key {key} must be true/false, got {value!r}")
        return value
    if isinstance(default, int):
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"config key {key} must be an integer, got {value!r}")
        return value
    if isinstance(default, float):
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"config key {key} must be a number, got {value!r}")
        return float(value)
    if isinstance(default, str):
        if not isinstance(value, str):
            raise ValueError(f"config key {key} must be a string, got {value!r}")
        return value
    if isinstance(default, tuple):
        if not isinstance(value, list | tuple) or (default and not value):
            raise ValueError(f"config key {key} must be a non-empty list, got {value!r}")
        # the element type: the default's, or the annotation's when the default is empty
        elem = type(default[0]) if default else _TUPLE_ELEMENTS.get(str(f.type))
        if elem is None:  # pragma: no cover - a field type this reader does not know
            raise ValueError(f"config key {key}: unsupported type {f.type}")
        out = []
        for v in value:
            if elem is float and isinstance(v, int | float) and not isinstance(v, bool):
                out.append(float(v))
            elif elem is int and isinstance(v, int) and not isinstance(v, bool):
                out.append(v)
            else:
                raise ValueError(f"config key {key} must hold {elem.__name__}s, got {v!r}")
        return tuple(out)
    raise ValueError(f"config key {key}: unsupported type")  # pragma: no cover


def from_table(cls: type[T], table: dict[str, Any], owner: str, base: T | None = None) -> T:
    """An instance of the dataclass ``cls`` with the values of ``table`` (unknown keys and wrong
    types raise ValueError naming the key); fields not in the table keep ``base``'s values, or
    the class defaults without a base."""
    if not isinstance(table, dict):
        raise ValueError(f"config [{owner}] must be a table, got {type(table).__name__}")
    names = {f.name: f for f in fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(table) - set(names))
    if unknown:
        raise ValueError(
            f"unknown config key(s) in [{owner}]: {', '.join(unknown)} "
            f"(known: {', '.join(sorted(names))})"
        )
    kwargs = {k: convert_value(owner, names[k], v) for k, v in table.items()}
    if base is not None:
        return dataclasses.replace(base, **kwargs)  # type: ignore[type-var]
    return cls(**kwargs)


def parse_assignments(items: list[str]) -> dict[str, Any]:
    """``["min_hits=3", "smoothing=0.8", "use_fusion=false"]`` -> a table of plain values.

    Each value is read as a TOML value (numbers, true/false, quoted strings, [lists]); a bare
    word that is not valid TOML is taken as a string. ValueError for an item without ``=``.
    """
    import tomllib

    table: dict[str, Any] = {}
    for item in items:
        name, sep, text = item.partition("=")
        name = name.strip().replace("-", "_")
        if not sep or not name:
            raise ValueError(f"bad setting {item!r}: expected NAME=VALUE")
        try:
            table[name] = tomllib.loads(f"v = {text.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            table[name] = text.strip()
    return table


def to_plain(obj: Any) -> Any:
    """Plain nested data (tuples as lists) of a settings dataclass; ``from_table`` inverts it."""

    def plain(v: Any) -> Any:
        if isinstance(v, tuple | list):
            return [plain(x) for x in v]
        if isinstance(v, dict):
            return {k: plain(x) for k, x in v.items()}
        return v

    return plain(dataclasses.asdict(obj))
