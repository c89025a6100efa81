"""Running mapping methods over sequences and writing run folders (the `map` / `compare` commands).

A *method factory* builds a fresh ``MappingMethod`` for one sequence. Methods that share the learned
detector share its detections: the first method records them (``RecordingSource``) and the others
replay them (``ReplaySource``), so a comparison runs the detector once per frame.
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from icmapper.data.types import Frame, PerceptionRange, Sequence
from icmapper.mapping.types import Detections, DetectionSource, MappingMethod

if TYPE_CHECKING:
    from icmapper.mapping.config import MapperConfig


class RecordingSource:
    """Wraps a source and keeps every frame's detections (for replay by other methods)."""

    def __init__(self, inner: DetectionSource) -> None:
        self.inner = inner
        self.records: dict[int, Detections] = {}

    def reset(self) -> None:
        self.inner.reset()

    def detect(self, frame: Frame) -> Detections:
        d = self.inner.detect(frame)
        self.records[frame.index] = d
        return d

    def __getattr__(self, name: str) -> Any:  # e.g. `.detector` of a NetworkDetector
        return getattr(self.inner, name)


class ReplaySource:
    """Replays recorded detections (queries dropped: replay is for methods without learned
    association)."""

    def __init__(self, records: dict[int, Detections]) -> None:
        self.records = records

    def reset(self) -> None:
        pass

    def detect(self, frame: Frame) -> Detections:
        if frame.index not in self.records:
            raise ValueError(f"no recorded detections for frame {frame.index}")
        d = self.records[frame.index]
        return Detections(d.classes, d.scores, d.points, None, d.gt_ids)


class NetworkUnits:
    """File detections with the learned detector's point normalisation (``detector.to_unit``),
    which the learned association needs: the source of a learned mapper that runs a checkpoint's
    association and fusion networks on a prediction file's detections and query features."""

    def __init__(self, inner: DetectionSource, detector: Any) -> None:
        self.inner = inner
        self.detector = detector

    def reset(self) -> None:
        self.inner.reset()

    def detect(self, frame: Frame) -> Detections:
        return self.inner.detect(frame)


#: Where to read how to train for real camera images (the image-domain note).
REAL_DATA_RECIPE = (
    'README.md, "On a nuScenes or Argoverse 2 download" (configs/nuscenes_newsplit.toml, '
    "configs/av2_newsplit.toml)"
)
#: Checkpoints whose image-domain note was printed in this process (printed once each).
_DOMAIN_NOTED: set[str] = set()

#: ``--detections`` forms, for help and errors.
DETECTIONS_USAGE = "'learned', 'oracle[:PRESET]' or 'file:PATH[:FORMAT][:RANGE]'"


@dataclass
class DetectionInput:
    """Where detections come from: the learned detector of a checkpoint, the noisy-GT oracle, or
    a prediction file (``icmapper.formats``).

    With a file, ``predictions`` is the read file and ``networks`` the checkpoint whose
    association and fusion networks the learned mapper runs on the file's detections — set only
    when the file carries query features for every detection (else IC-Mapper associates by
    position and does not fuse, as on the oracle). ``match(spec, sequences)`` pairs the file's
    frames with the source's before any method runs.
    """

    checkpoint: str | None = None
    oracle_noise: str | None = None  # preset name ("none", "low", "medium", "high")
    device: str = "cpu"
    seed: int = 0
    file: str | None = None
    predictions: Any = None  # formats.PredictionSet of ``file``
    networks: str | None = None
    matched: Any = None  # formats.PredictionInput once ``match`` ran

    @staticmethod
    def parse(
        detections: str, checkpoint: str | None, device: str = "cpu", seed: int = 0
    ) -> DetectionInput:
        """detections: "learned", "oracle[:PRESET]" or "file:PATH[:FORMAT][:RANGE]" (FORMAT a
        registered prediction format, recognised from the content when left out; RANGE e.g.
        "100x50" for formats that do not record it). A file is read (and checked) here."""
        if detections == "learned":
            if not checkpoint:
                raise ValueError("--detections learned needs --checkpoint PATH")
            if not Path(checkpoint).is_file():
                raise OSError(f"checkpoint {checkpoint} does not exist")
            return DetectionInput(checkpoint=checkpoint, device=device, seed=seed)
        if detections == "oracle" or detections.startswith("oracle:"):
            from icmapper.mapping.oracle import OracleNoise

            preset = detections.split(":", 1)[1] if ":" in detections else "low"
            OracleNoise.preset(preset)  # ValueError naming the presets, before any work
            return DetectionInput(oracle_noise=preset, device=device, seed=seed)
        if detections.startswith("file:"):
            return DetectionInput._parse_file(detections[5:], checkpoint, device, seed)
        raise ValueError(f"bad --detections {detections!r}; expected {DETECTIONS_USAGE}")

    @staticmethod
    def _parse_file(rest: str, checkpoint: str | None, device: str, seed: int) -> DetectionInput:
        import re

        from icmapper.formats import formats, read_predictions

        path, fmt, rng = rest, None, None
        for _ in range(2):  # peel ":RANGE" and ":FORMAT" off the end (a path may hold ':')
            head, sep, tail = path.rpartition(":")
            if not sep or Path(path).exists():
                break
            if rng is None and fmt is None and re.fullmatch(r"\d+(\.\d+)?x\d+(\.\d+)?", tail):
                path, rng = head, tail
            elif fmt is None and tail in formats():
                path, fmt = head, tail
            else:
                break
        if not path:
            raise ValueError(f"--detections file:PATH: no path; expected {DETECTIONS_USAGE}")
        preds = read_predictions(path, fmt, rng)
        networks = None
        if preds.has_queries and checkpoint:
            from icmapper.models.network import checkpoint_settings

            if not Path(checkpoint).is_file():
                raise OSError(f"checkpoint {checkpoint} does not exist")
            ck_range = checkpoint_settings(checkpoint)[0].name
            if ck_range != preds.range_name:
                raise ValueError(
                    f"{path}: predictions at range {preds.range_name}, but the checkpoint "
                    f"{checkpoint} (whose association and fusion would run on their query "
                    f"features) works at {ck_range}"
                )
            networks = checkpoint
        return DetectionInput(
            device=device, seed=seed, file=path, predictions=preds, networks=networks
        )

    def match(self, spec: str, sequences: list[Sequence]) -> None:
        """Pairs a prediction file's frames with the source's (no-op for other inputs);
        PredictionFileError names the first frame that does not fit."""
        if self.predictions is not None:
            from icmapper.formats.source import PredictionInput

            self.matched = PredictionInput(self.predictions, spec, sequences)
            for seq in sequences:
                self.matched.check_complete(seq)

    def note_image_domain(self, sequences: list[Sequence], stream: Any = None) -> bool:
        """Prints once per checkpoint (to ``stream``, default stderr) that a checkpoint trained
        on rendered images only is not expected to work on the real camera images among
        ``sequences``, and where the recipe for real data is. Returns whether it printed."""
        import sys

        if self.checkpoint is None or self.checkpoint in _DOMAIN_NOTED:
            return False
        real = [s.name for s in sequences if s.images == "real"]
        if not real:
            return False
        from icmapper.data.sources import may_have_real_images
        from icmapper.models.network import checkpoint_training_source

        trained = checkpoint_training_source(self.checkpoint)
        if not trained or may_have_real_images(trained):
            return False
        _DOMAIN_NOTED.add(self.checkpoint)
        print(
            f"note: checkpoint {self.checkpoint} was trained on synthetic renders only "
            f"(data.source {trained!r}); it is not expected to work on real camera images "
            f"({len(real)} sequence(s) here, e.g. {real[0]}). To map real data, train on it: "
            f"{REAL_DATA_RECIPE}.",
            file=stream if stream is not None else sys.stderr,
        )
        return True

    @property
    def needs_images(self) -> bool:
        return self.checkpoint is not None

    def perception_range(self) -> PerceptionRange:
        """The range of the run: the checkpoint's, the file's, or 60x30 for the oracle."""
        from icmapper.data.types import RANGE_60x30

        if self.checkpoint:
            from icmapper.models.network import checkpoint_settings

            return checkpoint_settings(self.checkpoint)[0]
        if self.predictions is not None:
            return PerceptionRange.from_name(self.predictions.range_name)
        return RANGE_60x30


#: A progress callback of the Python API's long loops: called after every frame with (frames
#: done, frames in all), e.g. ``map_sequence(..., on_frame=lambda done, n: print(done, n))``.
FrameCallback = Callable[[int, int], None]

#: (sequence, recorded detections or None) -> (method, its recorder or None)
MethodFactory = Callable[
    [Sequence, dict[int, Detections] | None], tuple[MappingMethod, RecordingSource | None]
]


def method_factory(
    name: str, inp: DetectionInput, rng: PerceptionRange, config: MapperConfig | None = None
) -> MethodFactory:
    """A function (sequence, recorded detections or None) -> (method, recorder or None) for the
    registered method ``name`` (``mapping.methods``), every method under the same ``config``
    (None: the defaults, and the checkpoint's detection threshold for the learned mapper).

    With the learned detector, the checkpoint is loaded once per factory; the first method that
    runs the detector on a sequence records its detections, and the methods that need no query
    features replay them (``RecordingSource`` / ``ReplaySource``)."""
    from icmapper.mapping.config import MapperConfig
    from icmapper.mapping.mapper import Mapper
    from icmapper.mapping.methods import method

    info = method(name)
    cfg = config or MapperConfig()
    live = inp.checkpoint is not None  # the learned detector runs on images

    def base_source(seq: Sequence) -> DetectionSource:
        """The detections of a method without the live detector: the file's or the oracle's."""
        if inp.file is not None:
            if inp.matched is None:
                raise ValueError("file detections: DetectionInput.match(spec, sequences) first")
            return inp.matched.source(seq)
        from icmapper.mapping.oracle import OracleDetector

        return OracleDetector(seq, rng=rng, noise=inp.oracle_noise or "low", seed=inp.seed)

    if not live and info.learned_only:
        raise ValueError(f"method {name} needs the learned detector (--detections learned)")

    if info.variant is not None:
        variant = info.variant
        built: list = []  # [Mapper, its NetworkDetector] once loaded

        def load(path: str) -> tuple[Mapper, Any]:
            if not built:  # load the checkpoint once; the Mapper is reset for every sequence
                built.append(
                    Mapper.from_checkpoint(path, config=config, device=inp.device, variant=variant)
                )
                built.append(built[0].source)
            return built[0], built[1]

        def make_mapper(seq: Sequence, records: dict[int, Detections] | None):
            if inp.networks is not None:  # the checkpoint's networks on the file's queries
                m, net_source = load(inp.networks)
                src = base_source(seq)
                _check_query_size(inp, net_source.detector)
                m.source = NetworkUnits(src, net_source.detector)
                return m, None
            if not live:
                return Mapper(base_source(seq), config=cfg, rng=rng, name=name), None
            m, net_source = load(inp.checkpoint)  # type: ignore[arg-type]
            m.source = net_source
            if m.config.use_association and records is None:
                rec = RecordingSource(net_source)
                m.source = rec
                return m, rec
            return m, None

        return make_mapper

    build = info.build
    assert build is not None
    net: list = []  # the learned detection source, once loaded

    def make_baseline(seq: Sequence, records: dict[int, Detections] | None):
        if not live:
            return build(base_source(seq), cfg, rng), None
        if records is not None:
            return build(ReplaySource(records), cfg, rng), None
        if not net:  # load the checkpoint once
            net.append(
                Mapper.from_checkpoint(inp.checkpoint, config=config, device=inp.device).source
            )
        rec = RecordingSource(net[0])
        return build(rec, cfg, rng), rec

    return make_baseline


def _check_query_size(inp: DetectionInput, detector: Any) -> None:
    """ValueError when the file's query features do not fit the checkpoint's networks."""
    dims = {f.queries.shape[1] for f in inp.predictions.frames if f.queries is not None}
    want = int(detector.cfg.channels)
    if dims and dims != {want}:
        raise ValueError(
            f"{inp.file}: query features of size {sorted(dims)}, but the checkpoint "
            f"{inp.networks} has {want} channels"
        )


def unique_track_ids(ids: NDArray[np.int64], start: int) -> tuple[NDArray[np.int64], int]:
    """Track ids valid for the run format (>= 0, unique within the frame): negative ids and
    repeats get fresh ids from ``start``. Returns the ids and the next fresh id."""
    out = np.asarray(ids, dtype=np.int64).copy()
    seen: set[int] = set()
    for j, v in enumerate(out.tolist()):
        if v < 0 or v in seen:
            out[j] = start
            start += 1
        seen.add(int(out[j]))
    return out, start


def map_sequence(
    method: MappingMethod,
    seq: Sequence,
    with_images: bool,
    progress: Any = None,
    reset: bool = True,
    on_frame: FrameCallback | None = None,
    keep: Collection[int] = (),
) -> tuple[list[Any], Any]:
    """Runs one method over one sequence: (per-frame FramePredictions, global map).
    ``progress``: a bar (``icmapper.progress``) advanced by one per frame; ``on_frame``: a
    callback (frames done, frames of the sequence) after every frame (opt-in progress for the
    Python API). ``reset=False`` continues the method's current state (a city map continued
    drive after drive: the caller resets it and loads the map first; ``keep``: the ids of the
    map it loaded, which the drive's check, ``MapperConfig.verify``, leaves alone). The
    finished map is checked (``mapping.verify``) and cleaned (``mapping.map_nms``) as the
    method's config asks."""
    from icmapper.eval.runfmt import FramePredictions
    from icmapper.mapping.map_nms import map_nms
    from icmapper.mapping.verify import check

    if reset:
        method.reset()
    frames = []
    seen = []  # per frame: (pose (4, 4), the detections the method received, without their
    # query features: the check reads the geometry, and a long drive need not hold the rest)
    fresh = 1 << 50
    for i in range(len(seq)):
        frame = seq.frame(i, with_images=with_images)
        res = method.step(frame)
        seen.append((np.asarray(frame.pose, np.float64), replace(res.detections, queries=None)))
        ids, fresh = unique_track_ids(res.track_ids, fresh)
        frames.append(
            FramePredictions(
                frame_index=i,
                pose=np.asarray(frame.pose, dtype=np.float64),
                classes=res.detections.classes.astype(np.int64),
                scores=res.detections.scores.astype(np.float64),
                points=np.asarray(res.points, dtype=np.float32),
                track_ids=ids,
                timestamp=float(frame.timestamp),
            )
        )
        if progress is not None:
            progress.update(1)
        if on_frame is not None:
            on_frame(i + 1, len(seq))
    gmap = method.finish()
    if method.config.verify:
        check(gmap, seen, method.config, method.rng, keep).apply(gmap)
    if method.config.map_nms:
        map_nms(gmap, method.config)
    return frames, gmap
