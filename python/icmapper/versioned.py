"""The header of the files icmapper writes as one object (JSON files, torch checkpoints): a
``format`` name and an integer ``version``. ``check_versioned`` is the one check of it for their
readers; it names the file and reads nothing itself."""

from __future__ import annotations

from typing import Any


def check_versioned(obj: Any, fmt: str, version: int, where: str, what: str) -> dict[str, Any]:
    """``obj`` when it is a dict whose ``format`` is ``fmt`` and ``version`` is ``version``;
    ValueError starting with ``where`` (the file) and naming ``what`` it should be otherwise."""
    if not isinstance(obj, dict) or obj.get("format") != fmt:
        raise ValueError(f"{where}: not an icmapper {what}")
    if obj.get("version") != version:
        raise ValueError(f"{where}: version {obj.get('version')}, this build reads {version}")
    return obj
