"""``icmapper map --city CITY --city-mode update --source SPEC``: drives through a city whose map
exists; what changed on the road is detected (``city.update``) and the city map brought up to
date, with a change report.

An update writes, in the city folder::

    updates.json              the update log (format "icmapper-city-updates", version 1): one
                              entry per update (its drives, detections, the counts of changes)
    updates/<k>/before.icmap  the city map as it was before update k (never updated)
    updates/<k>/after.icmap   the city map after update k
    updates/<k>/changes.geojson
                              update k's confirmed changes (``changes_report``)
    updates/<k>/true_changes.json
                              the true changes, where the drives' source knows them
                              (``sim-city-changed``)
    updates/<k>/changes.png   the picture: unchanged grey, removed red, added green, moved orange
    changes.geojson           the latest update's changes (the same file)
    city.icmap                the updated city map (also city.geojson)

The city map's atomic rename is the commit point: everything of update k is written before it,
the log after it, so an update killed at any point leaves a valid city map, either the old one
or the new one. Drives of another city (another world) are refused before anything is written.
"""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from icmapper.atomic import atomic_path, write_text_atomic
from icmapper.city.manifest import CITY_MAP, read_manifest, read_versioned
from icmapper.city.update import (
    Change,
    ChangeDetector,
    UpdateConfig,
    apply_changes,
    mark_map_errors,
)
from icmapper.data.types import CHANGE_TYPES

UPDATES = "updates.json"
UPDATES_FORMAT = "icmapper-city-updates"
UPDATES_VERSION = 1


@dataclass
class UpdateEntry:
    """One update of a city map: its number ``index`` (folder ``updates/<index>``), the source
    specs, the drives (drive id, sequence name), the detections, the counts of confirmed changes
    per type, and whether the true changes are known."""

    index: int
    specs: list[str]
    drives: list[tuple[int, str]]
    detections: str
    counts: dict[str, int]
    frames: int = 0
    true_changes: bool = False


@dataclass
class UpdateLog:
    updates: list[UpdateEntry] = field(default_factory=list)
    format: str = UPDATES_FORMAT
    version: int = UPDATES_VERSION


def read_updates(city: str | os.PathLike) -> UpdateLog:
    """The update log of a city folder (empty when it has none); ValueError naming the file
    when it is not one this build reads."""
    path = Path(city) / UPDATES
    if not path.is_file():
        return UpdateLog()
    raw = read_versioned(path, UPDATES_FORMAT, UPDATES_VERSION, "city update log")
    try:
        entries = [UpdateEntry(**u) for u in raw["updates"]]
    except (TypeError, KeyError) as exc:
        raise ValueError(f"{path}: malformed update log ({exc})") from None
    for e in entries:
        e.drives = [(int(d), str(n)) for d, n in e.drives]
    return UpdateLog(entries)


def next_drive_id(city: str | os.PathLike) -> int:
    """The next free drive id of a city folder: above its drives' and its updates' drives'."""
    from icmapper.city.manifest import is_city_run

    ids = [d.index for d in read_manifest(city).drives] if is_city_run(city) else []
    ids += [d for u in read_updates(city).updates for d, _ in u.drives]
    return max(ids, default=-1) + 1


def _covered(poses: NDArray[np.float64], rng: Any, margin: float) -> Any:
    """(m, 2) world points -> (m,) bool: inside the range (shrunk by ``margin``) of any pose."""
    from icmapper.data.gt import in_range_counts

    def covered(points: NDArray[np.float64]) -> NDArray[np.bool_]:
        return in_range_counts(points, poses, rng, margin) > 0

    return covered


def _update_seed(seed: int, drive: int) -> int:
    """The detection noise seed of an update drive: its own, not the seed the city was mapped
    with (so that an oracle's noise is not the noise baked into the stored map)."""
    return int(np.random.SeedSequence([int(seed), 0x0D47E, int(drive)]).generate_state(1)[0])


class _Detections:
    """Detection sources of an update run: the oracle, a prediction file or the checkpoint's
    detector (loaded once)."""

    def __init__(self, inp: Any, rng: Any) -> None:
        self.inp, self.rng = inp, rng
        self._net: Any = None

    def source(self, seq: Any, drive: int) -> Any:
        inp = self.inp
        if inp.file is not None:
            return inp.matched.source(seq)
        if inp.checkpoint is None:
            from icmapper.mapping.oracle import OracleDetector

            noise = inp.oracle_noise or "low"
            return OracleDetector(seq, self.rng, noise, seed=_update_seed(inp.seed, drive))
        if self._net is None:
            from icmapper.mapping.mapper import Mapper

            self._net = Mapper.from_checkpoint(inp.checkpoint, device=inp.device).source
        self._net.reset()
        return self._net


@dataclass
class UpdateResult:
    """What an update did: its log entry, the confirmed changes (applied), the folder."""

    entry: UpdateEntry
    changes: list[Change]
    folder: Path


def update_city(
    city: str | os.PathLike,
    specs: list[str],
    detections: str,
    checkpoint: str | None = None,
    device: str = "cpu",
    seed: int = 0,
    image_size: tuple[int, int] = (64, 176),
    config: UpdateConfig | None = None,
    log: Any = print,
    progress: bool = True,
) -> UpdateResult:
    """Runs the drives of ``specs`` through the city map of ``city``, detects what changed and
    updates the map (module docstring). ValueError (naming the file or the drive) for a folder
    that is not a city run of this format, a city without a map, a drive of another city or a
    perception range other than the city's."""
    from icmapper._icmap import GlobalMap
    from icmapper.city.run import city_sequences
    from icmapper.data.sources import open_source, resolve_spec
    from icmapper.mapping.run import DetectionInput
    from icmapper.progress import progress as progress_bar

    city = Path(city)
    manifest = read_manifest(city)  # refuses another format or version
    updates = read_updates(city)
    map_path = city / CITY_MAP
    if not map_path.is_file():
        raise ValueError(f"{map_path}: the city has no map to update (map drives into it first)")
    inp = DetectionInput.parse(detections, checkpoint, device, seed)
    rng = inp.perception_range()
    if rng.name != manifest.range_name:
        raise ValueError(
            f"{city} was mapped at range {manifest.range_name}; these detections work at {rng.name}"
        )
    base = city_sequences(manifest)
    if not base:
        raise ValueError(f"{city / 'city.json'}: no successful drive to know the city by")
    world_name = base[0].world.name
    specs = [resolve_spec(s) for s in specs]
    done = {n for u in updates.updates for _, n in u.drives}
    drives: list[tuple[str, Any]] = []
    for spec in specs:
        seqs = open_source(spec, image_size=image_size, seed=seed, render=inp.needs_images)
        inp.match(spec, seqs)
        for seq in seqs:
            if seq.world.name != world_name:
                raise ValueError(
                    f"source {spec!r}: drive {seq.name} is in {seq.world.name!r}, but the city "
                    f"map {map_path} is of {world_name!r}"
                )
            if seq.name in done:
                log(f"drive {seq.name} already updated the city; skipped")
                continue
            done.add(seq.name)
            drives.append((spec, seq))
    gmap = GlobalMap.load(str(map_path))
    base_poses = np.concatenate([np.asarray(s.poses) for s in base])  # (sum T, 4, 4)
    config = config or UpdateConfig()
    detector = ChangeDetector(gmap, rng, _covered(base_poses, rng, config.margin), config)
    sources = _Detections(inp, rng)
    first = next_drive_id(city)
    ids = [(first + k, seq.name) for k, (_, seq) in enumerate(drives)]
    total = sum(len(seq) for _, seq in drives)
    bar = progress_bar(total, f"update {city.name}", unit="frame", enabled=progress)
    for (drive, _), (_, seq) in zip(ids, drives, strict=True):
        src = sources.source(seq, drive)
        for i in range(len(seq)):
            frame = seq.frame(i, with_images=inp.needs_images)
            det = src.detect(frame)
            detector.observe((drive, i), frame.pose, det.classes, det.scores, det.points)
            bar.update(1)
    bar.close()
    replay = _history_replay(city, manifest, gmap, rng, config)
    changes = detector.decide(reference=replay)
    mark_map_errors(changes, replay.decide())
    apply_changes(gmap, changes, drive=first)
    index = len(updates.updates)
    folder = city / "updates" / f"{index:04d}"
    truth = _true_changes([spec for spec, _ in drives])
    entry = UpdateEntry(
        index, sorted({spec for spec, _ in drives}), ids, detections,
        {t: sum(c.change == t and c.cause == "road" for c in changes) for t in CHANGE_TYPES},
        total, truth is not None,
    )  # fmt: skip
    _save(city, folder, gmap, changes, truth, entry, updates, [seq for _, seq in drives])
    return UpdateResult(entry, changes, folder)


def _history_replay(
    city: Path, manifest: Any, gmap: Any, rng: Any, config: UpdateConfig
) -> ChangeDetector:
    """The change detector fed with the city's own drives (their recorded predictions,
    replayed): what they disagree with the map about (``decide``) are map errors, not changes of
    the road, and their offsets and sightings are the reference of the update's."""
    from icmapper.eval.runfmt import read_run

    runs = [read_run(city / d.run) for d in manifest.ok_drives()]
    poses = np.concatenate([s.poses for r in runs for s in r.sequences])  # (sum T, 4, 4)
    replay = ChangeDetector(gmap, rng, _covered(poses, rng, config.margin), config)
    for d, run in zip(manifest.ok_drives(), runs, strict=True):
        for seq in run.sequences:
            for t in range(len(seq)):
                fp = seq.frame(t)
                replay.observe((d.index, fp.frame_index), fp.pose, fp.classes, fp.scores, fp.points)
    return replay


def _true_changes(specs: list[str]) -> list[Any] | None:
    """The true changes of the drives' sources (None unless every source knows them and they
    agree: one changed city)."""
    from icmapper.data.sim.changes import spec_true_changes

    known = [spec_true_changes(s) for s in specs]
    if not known or any(k is None for k in known):
        return None
    first = [c.to_json() for c in known[0] or []]
    if any([c.to_json() for c in k or []] != first for k in known[1:]):
        return None
    return known[0]


def _save(
    city: Path,
    folder: Path,
    gmap: Any,
    changes: list[Change],
    truth: list[Any] | None,
    entry: UpdateEntry,
    updates: UpdateLog,
    seqs: list[Any],
) -> None:
    """Writes the update (module docstring: the order makes the city map's rename the commit
    point)."""
    from icmapper.city.changes_report import changes_geojson, plot_changes
    from icmapper.georef import write_map_geojsons

    folder.mkdir(parents=True, exist_ok=True)
    with atomic_path(folder / "before.icmap") as tmp:
        shutil.copyfile(city / CITY_MAP, tmp)
    gmap.save(str(folder / "after.icmap"), compact=True)
    report = json.dumps(changes_geojson(changes, entry.index, seqs[0].world.geo if seqs else ""))
    write_text_atomic(folder / "changes.geojson", report)
    if truth is not None:
        write_text_atomic(
            folder / "true_changes.json",
            json.dumps({"changes": [c.to_json() for c in truth]}, indent=1),
        )
    plot_changes(
        folder / "before.icmap", changes, seqs, folder / "changes.png",
        title=f"update {entry.index} of {city.name}: {sum(entry.counts.values())} change(s) of "
        f"the road, {len(changes) - sum(entry.counts.values())} map error(s)",
    )  # fmt: skip
    gmap.save(str(city / CITY_MAP), compact=True)  # the commit point
    updates.updates.append(entry)
    write_text_atomic(city / UPDATES, json.dumps(asdict(updates), indent=1))
    write_text_atomic(city / "changes.geojson", report)
    write_map_geojsons(gmap, city / "city", seqs[0].world.geo if seqs else "")


def changes_table(result: UpdateResult) -> str:
    """Markdown: confirmed changes per type and class, then one line per change."""
    from icmapper.data.types import CLASS_NAMES

    types = CHANGE_TYPES
    lines = [
        f"## City update {result.entry.index}: {len(result.changes)} change(s) from "
        f"{len(result.entry.drives)} drive(s), {result.entry.frames} frames",
        "",
        "| Class | " + " | ".join(types) + " |",
        "|---|" + "---|" * len(types),
    ]
    road = [ch for ch in result.changes if ch.cause == "road"]
    lines[0] = (
        f"## City update {result.entry.index}: {len(road)} change(s) of the road applied "
        f"({len(result.changes) - len(road)} map error(s) reported) from "
        f"{len(result.entry.drives)} drive(s), {result.entry.frames} frames"
    )
    for c, name in enumerate(CLASS_NAMES):
        n = [sum(ch.cls == c and ch.change == t for ch in road) for t in types]
        lines.append(f"| {name} | " + " | ".join(str(k) for k in n) + " |")
    lines.append("")
    for ch in result.changes:
        ev = ch.evidence
        extra = f", offset {ch.offset:+.2f} m" if ch.change == "moved" else ""
        if ch.cause != "road":
            extra += "; the city's drives saw it before: a map error, reported, not applied"
        what = ch.instance if ch.instance >= 0 else "(new)"
        lines.append(
            f"- {ch.change} {ch.class_name} {what}: expected in {len(ev.expected)} "
            f"frame(s), seen {len(ev.seen)}, missed {len(ev.missed)}{extra}"
        )
    return "\n".join(lines) + "\n"
