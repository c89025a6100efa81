"""Running mapping methods over sequences and writing run folders (the `map` / `compare` commands).

A *method factory* builds a fresh ``MappingMethod`` for one sequence. Methods that share the learned
detector share its detections: the first method records them (``RecordingSource``) and the others
replay them (``ReplaySource``), so a comparison runs the detector once per frame.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
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


@dataclass
class DetectionInput:
    """Where detections come from: the learned detector of a checkpoint or the noisy-GT oracle."""

    checkpoint: str | None = None
    oracle_noise: str | None = None  # preset name ("none", "low", "medium", "high")
    device: str = "cpu"
    seed: int = 0

    @staticmethod
    def parse(
        detections: str, checkpoint: str | None, device: str = "cpu", seed: int = 0
    ) -> DetectionInput:
        """detections: "learned" or "oracle[:PRESET]"."""
        if detections == "learned":
            if not checkpoint:
                raise ValueError("--detections learned needs --checkpoint PATH")
            if not Path(checkpoint).is_file():
                raise OSError(f"checkpoint {checkpoint} does not exist")
            return DetectionInput(checkpoint=checkpoint, device=device, seed=seed)
        if detections == "oracle" or detections.startswith("oracle:"):
            preset = detections.split(":", 1)[1] if ":" in detections else "low"
            return DetectionInput(oracle_noise=preset, device=device, seed=seed)
        raise ValueError(
            f"bad --detections {detections!r}; expected 'learned' or 'oracle[:PRESET]'"
        )

    @property
    def needs_images(self) -> bool:
        return self.checkpoint is not None


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

    def oracle(seq: Sequence) -> DetectionSource:
        from icmapper.mapping.oracle import OracleDetector

        return OracleDetector(seq, rng=rng, noise=inp.oracle_noise or "low", seed=inp.seed)

    if inp.checkpoint is None and info.learned_only:
        raise ValueError(f"method {name} needs the learned detector (--detections learned)")

    if info.variant is not None:
        variant = info.variant
        built: list = []  # [Mapper, its NetworkDetector] once loaded

        def make_mapper(seq: Sequence, records: dict[int, Detections] | None):
            if inp.checkpoint is None:
                return Mapper(oracle(seq), config=cfg, rng=rng, name=name), None
            if not built:  # load the checkpoint once; the Mapper is reset for every sequence
                built.append(
                    Mapper.from_checkpoint(
                        inp.checkpoint, config=config, device=inp.device, variant=variant
                    )
                )
                built.append(built[0].source)
            m, net_source = built
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
        if inp.checkpoint is None:
            return build(oracle(seq), cfg, rng), None
        if records is not None:
            return build(ReplaySource(records), cfg, rng), None
        if not net:  # load the checkpoint once
            net.append(
                Mapper.from_checkpoint(inp.checkpoint, config=config, device=inp.device).source
            )
        rec = RecordingSource(net[0])
        return build(rec, cfg, rng), rec

    return make_baseline


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
) -> tuple[list[Any], Any]:
    """Runs one method over one sequence: (per-frame FramePredictions, global map).
    ``reset=False`` continues the method's current state (a city map continued drive after
    drive: the caller resets it and loads the map first)."""
    from icmapper.eval.runfmt import FramePredictions

    if reset:
        method.reset()
    frames = []
    fresh = 1 << 50
    for i in range(len(seq)):
        frame = seq.frame(i, with_images=with_images)
        res = method.step(frame)
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
    return frames, method.finish()
