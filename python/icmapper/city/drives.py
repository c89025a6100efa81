"""One drive of a city run: mapped with the run's method, written as a standard run folder, its
map returned as native bytes tagged with the drive's id (what a Ray worker sends back).

``DriveMapper`` holds what every drive of a city run shares: the method factory (so the networks
of a checkpoint load once per process, or once per Ray worker) and the opened sources.
"""

from __future__ import annotations

import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from icmapper.mapping.run import FrameCallback


@dataclass(frozen=True)
class CitySettings:
    """What every drive of a city run is mapped with (plain values: it travels to Ray workers).
    ``config`` is a ``MapperConfig.to_dict()``."""

    method: str
    detections: str
    checkpoint: str | None
    config: dict[str, Any]
    image_size: tuple[int, int]
    seed: int = 0
    device: str = "cpu"


@dataclass(frozen=True)
class DriveTask:
    """Drive ``index`` (its id in the city map's provenance): sequence ``sequence`` of source
    ``spec`` (``frames`` keyframes), written to the run folder ``run_dir``."""

    index: int
    spec: str
    sequence: str
    run_dir: str
    frames: int = 0


@dataclass
class DriveOutcome:
    """What became of a drive: "ok" with its map (native bytes, tagged with the drive) or
    "failed" with the error; frames mapped and seconds."""

    index: int
    status: str
    error: str = ""
    frames: int = 0
    seconds: float = 0.0
    map_bytes: bytes | None = None


class DriveMapper:
    """Maps drives with the settings of a city run (see the module docstring)."""

    def __init__(self, settings: CitySettings) -> None:
        from icmapper.mapping.config import MapperConfig
        from icmapper.mapping.run import DetectionInput, method_factory

        self.settings = settings
        self.inp = DetectionInput.parse(
            settings.detections, settings.checkpoint, settings.device, settings.seed
        )
        self.rng = self.inp.perception_range()
        self.config = MapperConfig.from_dict(settings.config)
        self.factory = method_factory(settings.method, self.inp, self.rng, self.config)
        self._sources: dict[str, dict[str, Any]] = {}

    def sequence(self, spec: str, name: str) -> Any:
        """Sequence ``name`` of source ``spec`` (sources opened once per mapper)."""
        if spec not in self._sources:
            from icmapper.data.sources import open_source

            seqs = open_source(
                spec,
                image_size=self.settings.image_size,
                seed=self.settings.seed,
                render=self.inp.needs_images,
            )
            self.inp.match(spec, seqs)  # a prediction file's frames against the source's
            self.inp.note_image_domain(seqs)
            self._sources[spec] = {s.name: s for s in seqs}
        by_name = self._sources[spec]
        if name not in by_name:
            raise ValueError(f"source {spec!r} has no sequence {name!r}")
        return by_name[name]

    def map_drive(
        self,
        task: DriveTask,
        start_map: bytes | None = None,
        on_frame: FrameCallback | None = None,
    ) -> DriveOutcome:
        """Maps one drive into its run folder; never raises for a failing drive (the outcome
        says "failed" and why). ``start_map``: continue this map (native bytes) instead of
        starting empty ("continue" mode; the method must support it). ``on_frame``: called
        after every frame with (frames done, frames of the drive)."""
        t0 = time.perf_counter()
        try:
            return self._map(task, start_map, t0, on_frame)
        except Exception as exc:  # a bad drive is reported, the city goes on without it
            where = traceback.extract_tb(exc.__traceback__)[-1]
            return DriveOutcome(
                task.index,
                "failed",
                f"{type(exc).__name__}: {exc} ({Path(where.filename).name}:{where.lineno})",
                seconds=time.perf_counter() - t0,
            )

    def _map(
        self,
        task: DriveTask,
        start_map: bytes | None,
        t0: float,
        on_frame: FrameCallback | None,
    ) -> DriveOutcome:
        from icmapper._icmap import GlobalMap
        from icmapper.eval.runfmt import RunWriter
        from icmapper.mapping.run import map_sequence

        seq = self.sequence(task.spec, task.sequence)
        method, _ = self.factory(seq, None)
        method.reset()
        before: dict[int, int] = {}  # a continued map's instances: id -> observations
        if start_map is not None:
            restore = getattr(method, "restore", None)
            tracker = getattr(method, "tracker", None)
            if restore is None or tracker is None:
                raise ValueError(f"method {self.settings.method} cannot continue a map")
            gmap = GlobalMap.from_bytes(start_map)
            ids = gmap.ids()
            tracker.reserve_ids(int(ids.max()) + 1 if len(ids) else 0)
            restore(gmap, alias={})
            before = {int(i): gmap.info(int(i))["observations"] for i in ids.tolist()}
        frames, gmap = map_sequence(
            method, seq, self.inp.needs_images, reset=False, on_frame=on_frame, keep=before
        )
        if start_map is None:
            gmap.tag_drive(task.index)
        else:  # the instances this drive inserted or merged into
            seen = [i for i in gmap.ids().tolist() if gmap.info(i)["observations"] != before.get(i)]
            gmap.tag_drive(task.index, ids=seen)
        with RunWriter(task.run_dir, self.settings.method, task.spec, self.rng) as writer:
            writer.add_sequence(seq.name, frames, gmap)
        return DriveOutcome(
            task.index, "ok", frames=len(frames), seconds=time.perf_counter() - t0,
            map_bytes=gmap.to_bytes(),
        )  # fmt: skip
