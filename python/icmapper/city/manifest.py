"""The city run folder and its manifest ``city.json``.

Layout of a city run ``CITY/``::

    city.json            this manifest (format "icmapper-city", version 1)
    city.icmap           the city map (native file, compact: coordinates on a 0.1 mm grid;
                         provenance: the drives of each instance)
    city.geojson         the city map in the local map frame (+ city.wgs84.geojson where located)
    city.png             the city map beside the cross-drive ground truth
    drives/<k>-<name>/   one standard run folder per drive (run.json, <name>.npz, <name>.icmap)

The manifest records how the city was built (method, detections, checkpoint, perception range,
mode, the ``MapperConfig``, the merge settings) and every drive: its source spec and sequence
name, its run folder, whether it succeeded (a failed drive keeps its error and is left out of the
city map). A city run is extended by running more drives into the same folder: drives already
listed are not mapped again. Written atomically.
"""

from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from icmapper.atomic import write_text_atomic
from icmapper.versioned import check_versioned

FORMAT = "icmapper-city"
VERSION = 1
MANIFEST = "city.json"
CITY_MAP = "city.icmap"

#: How a city map is built: "merge" (every drive mapped alone, then the drive maps merged) or
#: "continue" (one mapper continues the city map drive after drive, with re-identification).
MODES = ("merge", "continue")


@dataclass
class DriveEntry:
    """One drive of a city run: ``index`` (its drive id in the map's provenance), the source
    ``spec`` and the ``sequence`` name in it, the run folder (relative to the city folder),
    ``status`` "ok" or "failed" (then ``error``), frames and seconds."""

    index: int
    spec: str
    sequence: str
    run: str
    status: str = "ok"
    error: str = ""
    frames: int = 0
    seconds: float = 0.0


@dataclass
class CityManifest:
    method: str
    detections: str
    checkpoint: str | None
    range_name: str
    mode: str
    mapper_config: dict[str, Any]
    drives: list[DriveEntry] = field(default_factory=list)
    format: str = FORMAT
    version: int = VERSION

    def ok_drives(self) -> list[DriveEntry]:
        return [d for d in self.drives if d.status == "ok"]

    def next_index(self) -> int:
        return max((d.index for d in self.drives), default=-1) + 1


def is_city_run(path: str | os.PathLike) -> bool:
    return (Path(path) / MANIFEST).is_file()


def read_versioned(path: Path, fmt: str, version: int, what: str) -> dict[str, Any]:
    """The JSON object of a city folder's file ``path`` of format ``fmt`` and ``version``;
    ValueError naming the file (and ``what`` it should be) otherwise."""
    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ValueError(f"{path}: not a readable {what} ({exc})") from None
    return check_versioned(raw, fmt, version, str(path), what)


def read_manifest(city: str | os.PathLike) -> CityManifest:
    """The manifest of a city folder (ValueError naming the file when it is not one)."""
    path = Path(city) / MANIFEST
    raw = read_versioned(path, FORMAT, VERSION, "city manifest")
    try:
        drives = [DriveEntry(**d) for d in raw.pop("drives")]
        return CityManifest(drives=drives, **raw)
    except (TypeError, KeyError) as exc:
        raise ValueError(f"{path}: malformed manifest ({exc})") from None


def write_manifest(city: str | os.PathLike, manifest: CityManifest) -> None:
    """Writes ``city.json`` atomically (temp file in the folder + rename)."""
    write_text_atomic(Path(city) / MANIFEST, json.dumps(asdict(manifest), indent=1))
