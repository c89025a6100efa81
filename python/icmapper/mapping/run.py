"""Running mapping methods over sequences and writing run folders (the `map` / `compare` commands).

A *method factory* builds a fresh ``MappingMethod`` for one sequence. Methods that share the learned
detector share its detections: the first method records them (``RecordingSource``) and the others
replay them (``ReplaySource``), so a comparison runs the detector once per frame.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from icmapper.data.types import Frame, PerceptionRange, Sequence
from icmapper.mapping.types import Detections, DetectionSource, MappingMethod

#: Methods of `icmapper map --method` / `compare`, in table order.
METHODS = (
    "icmapper",
    "icmapper-no-fusion",
    "icmapper-base",
    "icmapper-single-frame",
    "post-track",
    "vma",
    "cluster-fit",
    "polymerge",
)
_BASELINE_NAMES = {
    "post-track": "post_track",
    "vma": "vma_merge",
    "cluster-fit": "cluster_fit",
    "polymerge": "polymerge",
}


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
class DetectorSpec:
    """Where detections come from: the learned detector of a checkpoint or the noisy-GT oracle."""

    checkpoint: str | None = None
    oracle_noise: str | None = None  # preset name ("none", "low", "medium", "high")
    device: str = "cpu"
    seed: int = 0

    @staticmethod
    def parse(
        detections: str, checkpoint: str | None, device: str = "cpu", seed: int = 0
    ) -> DetectorSpec:
        """detections: "learned" or "oracle[:PRESET]"."""
        if detections == "learned":
            if not checkpoint:
                raise ValueError("--detections learned needs --checkpoint PATH")
            if not Path(checkpoint).is_file():
                raise OSError(f"checkpoint {checkpoint} does not exist")
            return DetectorSpec(checkpoint=checkpoint, device=device, seed=seed)
        if detections == "oracle" or detections.startswith("oracle:"):
            preset = detections.split(":", 1)[1] if ":" in detections else "low"
            return DetectorSpec(oracle_noise=preset, device=device, seed=seed)
        raise ValueError(
            f"bad --detections {detections!r}; expected 'learned' or 'oracle[:PRESET]'"
        )

    @property
    def needs_images(self) -> bool:
        return self.checkpoint is not None


def method_factory(
    method: str, spec: DetectorSpec, rng: PerceptionRange
) -> Callable[
    [Sequence, dict[int, Detections] | None], tuple[MappingMethod, RecordingSource | None]
]:
    """A function (sequence, recorded detections or None) -> (method, recorder or None)."""
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; expected one of {', '.join(METHODS)}")
    from icmapper.mapping.mapper import Mapper, MapperConfig

    def oracle(seq: Sequence) -> DetectionSource:
        from icmapper.mapping.oracle import OracleDetector

        return OracleDetector(seq, rng=rng, noise=spec.oracle_noise or "low", seed=spec.seed)

    if method.startswith("icmapper"):
        variant = method[len("icmapper-") :] if method != "icmapper" else "full"
        if spec.checkpoint is None and variant not in ("full", "base"):
            raise ValueError(f"method {method} needs the learned detector (--detections learned)")

        built: list = []  # [Mapper, its NetworkDetector] once loaded

        def make_mapper(seq: Sequence, records: dict[int, Detections] | None):
            if spec.checkpoint is None:
                m = Mapper(oracle(seq), config=MapperConfig(), rng=rng, name=method)
                return m, None
            if not built:  # load the checkpoint once; the Mapper is reset for every sequence
                built.append(
                    Mapper.from_checkpoint(spec.checkpoint, device=spec.device, variant=variant)
                )
                built.append(built[0].source)
            m, net_source = built
            m.source = net_source
            if variant in ("full", "no-fusion") and records is None:
                rec = RecordingSource(net_source)
                m.source = rec
                return m, rec
            return m, None

        return make_mapper

    from icmapper.mapping import baselines

    cls = baselines.BASELINES[_BASELINE_NAMES[method]]
    net: list = []  # the learned detection source, once loaded

    def make_baseline(seq: Sequence, records: dict[int, Detections] | None):
        if spec.checkpoint is None:
            return cls(oracle(seq)), None
        if records is not None:
            return cls(ReplaySource(records)), None
        if not net:  # load the checkpoint once
            net.append(Mapper.from_checkpoint(spec.checkpoint, device=spec.device).source)
        rec = RecordingSource(net[0])
        return cls(rec), rec

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
    method: MappingMethod, seq: Sequence, with_images: bool, progress: Any = None
) -> tuple[list[Any], Any]:
    """Runs one method over one sequence: (per-frame FramePredictions, global map)."""
    from icmapper.eval.runfmt import FramePredictions

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
