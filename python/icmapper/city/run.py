"""Build or extend a city run: map every new drive of the given sources, make the city map, write
the city folder (``manifest`` describes the layout).

Two modes (documented in docs/mapping.md, "City maps"):
- ``merge``: every drive is mapped on its own (in-process, one after another, or in parallel on
  Ray), the drive maps are merged by the engine (``GlobalMap.merge_map``, a tree in drive order);
  extending a city merges the new drives' maps into the existing city map. Right for many drives,
  any method, and parallel hardware; drives do not see each other's map.
- ``continue``: one IC-Mapper continues the city map drive after drive (the map loaded before each
  drive, new ids above its largest, re-identification against it), in-process. Right when later
  drives should be associated with and fused into what earlier drives mapped; sequential.

A drive that fails is recorded with its error and left out; the city map is saved after every
step (atomic engine writes), so a city run interrupted mid-way keeps a valid map and manifest.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from icmapper.city.drives import CitySettings, DriveMapper, DriveOutcome, DriveTask
from icmapper.city.manifest import (
    CITY_MAP,
    MODES,
    CityManifest,
    DriveEntry,
    is_city_run,
    read_manifest,
    write_manifest,
)
from icmapper.city.reduce import merge_bytes, tree_reduce

if TYPE_CHECKING:
    from icmapper.mapping.run import FrameCallback


def _drive_tasks(
    city: Path, specs: Sequence[str], manifest: CityManifest, settings: CitySettings
) -> list[DriveTask]:
    """One task per sequence of ``specs`` not yet in the manifest (by sequence name: a drive is
    the same drive whichever spec names it, e.g. sim-city:val:0:2 and sim-city:val:0:3 share two),
    with fresh drive ids."""
    from icmapper.data.sources import open_source

    done = {d.sequence for d in manifest.drives}
    index = manifest.next_index()
    tasks = []
    for spec in specs:
        for seq in open_source(
            spec, image_size=settings.image_size, seed=settings.seed, render=False
        ):
            if seq.name in done:
                continue
            done.add(seq.name)
            run = city / "drives" / f"{index:04d}-{seq.name}"
            tasks.append(DriveTask(index, spec, seq.name, str(run), len(seq)))
            index += 1
    return tasks


def _check_compatible(old: CityManifest, new: CityManifest, city: Path) -> None:
    from icmapper.mapping.config import MapperConfig

    # (A manifest written before a config field existed holds that field's default.)
    old.mapper_config = MapperConfig.from_dict(old.mapper_config).to_dict()
    for key in ("method", "detections", "checkpoint", "range_name", "mode", "mapper_config"):
        if getattr(old, key) != getattr(new, key):
            raise ValueError(
                f"{city} was built with {key} = {getattr(old, key)!r}; this run asks for "
                f"{getattr(new, key)!r} (use another --city folder)"
            )


def build_city(
    city: str | os.PathLike,
    specs: Sequence[str],
    settings: CitySettings,
    range_name: str,
    mode: str = "merge",
    workers: int = 0,
    ray_address: str | None = None,
    pictures: bool = True,
    log: Any = print,
    progress: bool = True,
    on_frame: FrameCallback | None = None,
) -> CityManifest:
    """Maps the drives of ``specs`` that the city run in ``city`` does not hold yet and updates
    its city map (see the module docstring). ``workers`` > 0 runs merge-mode drives on Ray (a
    local instance, or the cluster at ``ray_address``); 0 runs them in-process, reporting every
    frame: a progress bar or lines (``progress``; ``icmapper.progress``) and ``on_frame``
    (frames done, frames of all new drives), the Python API's opt-in callback. On Ray, drives
    report as they finish. Returns the manifest."""
    from icmapper._icmap import GlobalMap
    from icmapper.data.sources import resolve_spec
    from icmapper.mapping.config import MapperConfig

    specs = [resolve_spec(s) for s in specs]  # the manifest names the data from anywhere
    cfg = MapperConfig.from_dict(settings.config)
    gate, min_overlap, tol = cfg.city_gate, cfg.city_min_overlap, cfg.city_tolerance
    if mode not in MODES:
        raise ValueError(f"unknown city mode {mode!r}; expected one of {', '.join(MODES)}")
    city = Path(city)
    new = CityManifest(
        settings.method, settings.detections, settings.checkpoint, range_name, mode,
        dict(settings.config),
    )  # fmt: skip
    if is_city_run(city):
        manifest = read_manifest(city)
        _check_compatible(manifest, new, city)
    else:
        manifest = new
    tasks = _drive_tasks(city, specs, manifest, settings)  # a bad spec fails before any write
    city.mkdir(parents=True, exist_ok=True)
    city_map = city / CITY_MAP
    current = GlobalMap.load(str(city_map)).to_bytes() if city_map.is_file() else None
    log(f"city {city}: {len(tasks)} new drive(s), {len(manifest.drives)} already mapped")
    ticks = _FrameTicks(tasks, city, progress and not (workers and mode == "merge"), on_frame)
    if mode == "continue":
        if workers:
            log("note: continue mode maps drives one after another (workers ignored)")
        mapper = DriveMapper(settings)
        for task in tasks:
            outcome = mapper.map_drive(task, start_map=current, on_frame=ticks.of(task))
            _record(manifest, task, outcome, city, log)
            if outcome.map_bytes is not None:
                current = outcome.map_bytes
                GlobalMap.from_bytes(current).save(str(city_map), compact=True)
            write_manifest(city, manifest)
    else:
        if workers:
            from icmapper.city.ray_backend import run_on_ray

            outcomes, merged = run_on_ray(
                settings, tasks, workers, ray_address, gate, min_overlap, tol
            )
        else:
            mapper = DriveMapper(settings)
            outcomes = [mapper.map_drive(t, on_frame=ticks.of(t)) for t in tasks]
            maps = [o.map_bytes for o in sorted(outcomes, key=lambda o: o.index) if o.map_bytes]
            merged = (
                tree_reduce(maps, lambda a, b: merge_bytes(a, b, gate, min_overlap, tol))
                if maps
                else None
            )
        for task, outcome in zip(tasks, outcomes, strict=True):
            _record(manifest, task, outcome, city, log)
        if merged is not None:
            current = merge_bytes(current, merged, gate, min_overlap, tol) if current else merged
            GlobalMap.from_bytes(current).save(str(city_map), compact=True)
        write_manifest(city, manifest)
    ticks.close()
    failed = [d for d in manifest.drives if d.status != "ok"]
    if failed:
        log(f"{len(failed)} drive(s) failed and are left out of the city map:")
        for d in failed:
            log(f"  drive {d.index} {d.spec} {d.sequence}: {d.error}")
    if current is not None:
        _write_outputs(city, manifest, GlobalMap.from_bytes(current), settings, pictures)
    return manifest


class _FrameTicks:
    """Frame progress over every new drive of a city run (mapped in-process, one after another):
    the bar (or lines) and the caller's ``on_frame(done, total)``."""

    def __init__(
        self,
        tasks: list[DriveTask],
        city: Path,
        show: bool,
        on_frame: FrameCallback | None,
    ) -> None:
        from icmapper.progress import progress

        self.base: dict[int, int] = {}  # drive index -> frames of the drives before it
        acc = 0
        for t in tasks:
            self.base[t.index] = acc
            acc += t.frames
        self.total, self.done = acc, 0
        self.on_frame = on_frame
        self.bar = progress(self.total, f"city {city.name}", unit="frame", enabled=show)

    def of(self, task: DriveTask) -> FrameCallback:
        """The ``on_frame`` callback of ``map_drive`` for ``task``."""

        def frame(done: int, of: int) -> None:
            del of
            to = self.base[task.index] + done
            if to > self.done:
                self.bar.update(to - self.done)
                self.done = to
                if self.on_frame is not None:
                    self.on_frame(self.done, self.total)

        return frame

    def close(self) -> None:
        self.bar.close()


def _record(
    manifest: CityManifest, task: DriveTask, outcome: DriveOutcome, city: Path, log: Any
) -> None:
    run = os.path.relpath(task.run_dir, city)
    manifest.drives.append(
        DriveEntry(
            task.index, task.spec, task.sequence, run, outcome.status, outcome.error,
            outcome.frames, round(outcome.seconds, 3),
        )
    )  # fmt: skip
    log(f"drive {task.index} {task.sequence}: {outcome.status} {outcome.error}".rstrip())


def city_sequences(manifest: CityManifest, image_size: tuple[int, int] = (64, 176)) -> list[Any]:
    """The source sequences of the city's successful drives (for ground truth), in drive order."""
    from icmapper.data.sources import open_source

    opened: dict[str, dict[str, Any]] = {}
    out = []
    for d in manifest.ok_drives():
        if d.spec not in opened:
            opened[d.spec] = {
                s.name: s for s in open_source(d.spec, image_size=image_size, render=False)
            }
        out.append(opened[d.spec][d.sequence])
    return out


def _write_outputs(
    city: Path, manifest: CityManifest, gmap: Any, settings: CitySettings, pictures: bool
) -> None:
    import numpy as np

    from icmapper.data import gt as gt_mod
    from icmapper.data.types import PerceptionRange
    from icmapper.georef import write_map_geojsons
    from icmapper.mapping.plot import plot_global_maps

    seqs = city_sequences(manifest, settings.image_size)
    write_map_geojsons(gmap, city / "city", seqs[0].world.geo if seqs else "")  # local (+ WGS84)
    if not seqs:
        return
    if pictures:
        rng = PerceptionRange.from_name(manifest.range_name)
        gap = np.full((1, 4, 4), np.nan)  # breaks the drawn path between drives
        poses = np.concatenate([p for s in seqs for p in (np.asarray(s.poses), gap)])
        plot_global_maps(
            gmap,
            gt_mod.city_gt(seqs, rng),
            poses,
            city / "city.png",
            title=f"city map of {len(seqs)} drives ({manifest.method}, {manifest.mode})",
        )
