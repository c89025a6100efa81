"""A prediction file as the detection input of mapping and evaluation.

``PredictionInput`` pairs a read ``PredictionSet`` with a source's sequences (``frames.py``) once:
every predicted frame must name exactly one source frame, no frame twice, and every frame of the
mapped sequences must be in the file; a pose given by the file must be the source's (within
``POSE_TOLERANCE``); lidar-frame points (MapTR) are converted to the ego frame. Then
``source(seq)`` is a ``DetectionSource`` for that sequence (``FileDetections``) and ``frames(seq)``
its per-frame predictions for the evaluation.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from icmapper.data.types import Frame, Sequence
from icmapper.formats.frames import SourceFrames
from icmapper.formats.types import PredictedFrame, PredictionFileError, PredictionSet
from icmapper.mapping.types import Detections

#: Largest difference (metres / cosine units, any matrix entry) between a file's pose and the
#: source's.
POSE_TOLERANCE = 1e-3


class FileDetections:
    """The detections a prediction file holds for one sequence (a ``DetectionSource``).

    ``detect(frame)`` returns the frame's detections (classes, scores, points and, where the file
    has them, query features); a frame the file lacks raises PredictionFileError naming it.
    """

    def __init__(self, path: str, sequence: str, records: dict[int, PredictedFrame]) -> None:
        self.path = path
        self.sequence = sequence
        self.records = records

    def reset(self) -> None:
        pass

    def detect(self, frame: Frame) -> Detections:
        f = self.records.get(frame.index)
        if f is None:
            raise PredictionFileError(
                f"{self.path}: no predictions for frame {frame.index} (timestamp "
                f"{frame.timestamp:.6f}) of sequence {self.sequence!r}"
            )
        return Detections(
            f.classes.copy(),
            f.scores.copy(),
            f.points.copy(),
            None if f.queries is None else f.queries.copy(),
        )


def _to_ego(points: NDArray[np.float32], lidar_to_ego: NDArray[np.float64]) -> NDArray[np.float32]:
    """(k, n, 2) lidar-frame points -> ego frame with a (3, 3) planar transform."""
    r, t = lidar_to_ego[:2, :2], lidar_to_ego[:2, 2]
    return (points.astype(np.float64) @ r.T + t).astype(np.float32)  # (k, n, 2)


class PredictionInput:
    """A prediction file matched to a source's sequences (see the module docstring)."""

    def __init__(self, preds: PredictionSet, spec: str, sequences: list[Sequence]) -> None:
        self.preds = preds
        self.spec = spec
        self.sequences = {s.name: s for s in sequences}
        frames = SourceFrames.of(spec, sequences)
        if preds.point_frame == "lidar":
            frames.load_lidar()
        self.frame_names = frames
        self._by_seq: dict[str, dict[int, PredictedFrame]] = {s.name: {} for s in sequences}
        where = preds.path
        for f in preds.frames:
            s, t = frames.locate(f, where)
            seq = sequences[s]
            table = self._by_seq[seq.name]
            if t in table:
                raise PredictionFileError(
                    f"{where}: {f.name()}: frame {t} of sequence {seq.name!r} appears twice"
                )
            if f.pose is not None:
                diff = float(np.abs(f.pose - seq.poses[t]).max())
                if diff > POSE_TOLERANCE:
                    raise PredictionFileError(
                        f"{where}: {f.name()}: the pose differs from the source's frame {t} of "
                        f"sequence {seq.name!r} by {diff:.3g}"
                    )
            l2e = frames.lidar_to_ego[s]
            if preds.point_frame == "lidar" and l2e is not None and len(f):
                f = PredictedFrame(
                    f.token, f.timestamp, f.sequence, f.classes, f.scores,
                    _to_ego(f.points, l2e[t]), f.pose, f.track_ids, f.queries,
                )  # fmt: skip
            table[t] = f

    def check_complete(self, seq: Sequence) -> None:
        """PredictionFileError naming the first frame of ``seq`` the file lacks."""
        table = self._by_seq.get(seq.name)
        if table is None:
            raise PredictionFileError(f"{self.preds.path}: sequence {seq.name!r} is not matched")
        missing = [t for t in range(len(seq)) if t not in table]
        if missing:
            s = self.frame_names.index_of(seq.name)
            t = missing[0]
            raise PredictionFileError(
                f"{self.preds.path}: no predictions for frame {t} (token "
                f"{self.frame_names.tokens[s][t]!r}, timestamp {seq.timestamps[t]:.6f}) of "
                f"sequence {seq.name!r} ({len(missing)} of its {len(seq)} frames missing)"
            )

    def source(self, seq: Sequence) -> FileDetections:
        """The file's detections of ``seq`` as a ``DetectionSource`` (every frame checked)."""
        self.check_complete(seq)
        return FileDetections(self.preds.path, seq.name, self._by_seq[seq.name])

    def frames(self, seq: Sequence) -> list[PredictedFrame]:
        """The file's frames of ``seq`` in frame order (every frame checked), points in the ego
        frame."""
        self.check_complete(seq)
        table = self._by_seq[seq.name]
        return [table[t] for t in range(len(seq))]

    @property
    def has_queries(self) -> bool:
        return self.preds.has_queries
