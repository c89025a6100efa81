"""The registry of prediction file formats: one ``PredictionFormat`` per name of
``--detections file:PATH[:FORMAT]`` and ``icmapper export --format``.

A format is one module with a ``read(path, options)`` (and, where icmapper can write it, a
``write``) plus one ``register_format`` call at its end; ``sniff(data)`` recognises a file's parsed
JSON so that FORMAT can be left out. The command line's choices and help come from here.

The registry never imports its formats (each format module imports the registry: one import
edge); the package's ``__init__`` imports the built-in ones, so they are registered whenever
anything of ``icmapper.formats`` is imported.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from icmapper.formats.types import PredictionFileError, PredictionSet
from icmapper.registry import Registry


@dataclass(frozen=True)
class PredictionFormat:
    """A registered format: its name, one line of help, ``read(path, data, range_name)`` ->
    PredictionSet (``data``: the file's parsed JSON), ``sniff(data)`` -> whether a parsed file is
    of this format, and optionally ``write(path, predictions)`` (the export; atomic)."""

    name: str
    help: str
    read: Callable[[str, Any, str | None], PredictionSet]
    sniff: Callable[[Any], bool]
    write: Callable[[Path, PredictionSet], None] | None = None


_FORMATS: Registry[PredictionFormat] = Registry("prediction format")


def register_format(fmt: PredictionFormat) -> PredictionFormat:
    """Adds a format to the registry (ValueError for a name registered twice)."""
    return _FORMATS.register(fmt)


def formats() -> dict[str, PredictionFormat]:
    """Every registered format by name (the built-in ones: ``icmapper.formats.__init__``)."""
    return dict(_FORMATS)


def get_format(name: str) -> PredictionFormat:
    """The format registered as ``name`` (ValueError listing the known names)."""
    return _FORMATS.lookup(name)


def formats_help(writable: bool | None = None) -> str:
    """One line per registered format (for the command line); ``writable`` True / False: only
    the formats icmapper can / cannot write."""
    return "\n".join(
        f"  {n:<14} {f.help}"
        for n, f in formats().items()
        if writable is None or (f.write is not None) == writable
    )


def load_json(path: str | Path) -> Any:
    """A JSON file's content; PredictionFileError naming the file when missing or malformed."""
    p = Path(path)
    if not p.is_file():
        raise PredictionFileError(f"{p}: prediction file not found")
    try:
        with open(p, encoding="utf-8") as fh:
            return json.load(fh)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise PredictionFileError(f"{p}: not a readable JSON file ({exc})") from None


def read_predictions(
    path: str | Path, format: str | None = None, range_name: str | None = None
) -> PredictionSet:
    """Reads a prediction file as ``format`` (None: recognised from its content).

    range_name: the perception range the predictions were made at, where the file does not say
    (None: the file's, else "60x30"). Raises PredictionFileError (a ValueError) naming the file and,
    where one is at fault, the frame.
    """
    data = load_json(path)
    if format is None:
        found = [f for f in formats().values() if f.sniff(data)]
        if len(found) != 1:
            which = ", ".join(f.name for f in found) or "none"
            raise PredictionFileError(
                f"{path}: cannot tell the prediction format (matches: {which}); name it as "
                f"file:PATH:FORMAT with FORMAT one of {', '.join(formats())}"
            )
        fmt = found[0]
    else:
        fmt = get_format(format)
        if not fmt.sniff(data):
            raise PredictionFileError(f"{path}: not a {fmt.name!r} prediction file ({fmt.help})")
    return fmt.read(str(path), data, range_name)
