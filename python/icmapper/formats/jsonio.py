"""Small helpers the format modules share: atomic JSON writing and checked field access."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from icmapper.atomic import atomic_open
from icmapper.formats.types import PredictionFileError


def write_json_atomic(path: Path, data: Any) -> None:
    """Writes ``data`` as compact JSON to a temp file beside ``path``, then renames it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_open(path) as fh:
        json.dump(data, fh, separators=(",", ":"), allow_nan=False)


def field(obj: Any, key: str, kind: type | tuple[type, ...], where: str) -> Any:
    """``obj[key]`` checked to be a ``kind``; PredictionFileError naming ``where`` otherwise."""
    if not isinstance(obj, dict):
        raise PredictionFileError(f"{where}: expected a JSON object, got {type(obj).__name__}")
    if key not in obj:
        raise PredictionFileError(f"{where}: missing field {key!r}")
    value = obj[key]
    if not isinstance(value, kind) or isinstance(value, bool) and bool not in _kinds(kind):
        name = kind.__name__ if isinstance(kind, type) else "/".join(k.__name__ for k in kind)
        raise PredictionFileError(f"{where}: field {key!r} must be {name}, got {value!r:.60}")
    return value


def _kinds(kind: type | tuple[type, ...]) -> tuple[type, ...]:
    return kind if isinstance(kind, tuple) else (kind,)
