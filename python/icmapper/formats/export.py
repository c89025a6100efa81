"""A run folder's per-frame predictions (or a detector's recorded detections) as a
``PredictionSet``, and writing it in a registered format (``icmapper export``).

Frames are named the way ``frames.py`` names the source's frames: token, timestamp and sequence
name, with the ego pose; track ids as the run stores them. A run stores no query features.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from icmapper.data.types import Sequence
from icmapper.formats.frames import SourceFrames
from icmapper.formats.registry import get_format
from icmapper.formats.types import PredictedFrame, PredictionSet


def run_predictions(
    run_dir: str | os.PathLike, sequences: list[Sequence] | None = None
) -> PredictionSet:
    """Every frame of a run folder (``eval.runfmt``) as a PredictionSet in the icmapper
    convention. sequences: the run's source, when already opened (else opened from its spec:
    frames and poses are checked against it, and tokens come from it)."""
    from icmapper.eval.evaluate import check_run_frames
    from icmapper.eval.runfmt import read_run

    run = read_run(run_dir)
    if sequences is None:
        from icmapper.data.sources import open_source

        sequences = open_source(run.source, render=False)
    seqs = check_run_frames(run, sequences)
    names = SourceFrames.of(run.source, seqs)
    frames = []
    for s, (rs, seq) in enumerate(zip(run.sequences, seqs, strict=True)):
        for t in range(len(rs)):
            fp = rs.frame(t)
            frames.append(
                PredictedFrame(
                    names.tokens[s][t],
                    float(seq.timestamps[t]),
                    seq.name,
                    fp.classes.astype(np.int64),
                    fp.scores.astype(np.float32),
                    fp.points.astype(np.float32),
                    np.asarray(fp.pose, np.float64),
                    fp.track_ids.astype(np.int64),
                )  # fmt: skip
            )
    meta = {"method": run.method, "source": run.source}
    return PredictionSet("icmapper", str(run.path), frames, run.range_name, "ego", meta)


def detections_to_predictions(
    spec: str,
    sequences: list[Sequence],
    records: Mapping[str, Mapping[int, Any]],
    range_name: str,
    method: str = "detector",
) -> PredictionSet:
    """Recorded ``Detections`` (``records[sequence name][frame index]``, e.g. a
    ``RecordingSource``'s) as a PredictionSet: classes, scores, points and query features, named
    by token, timestamp and sequence, with the source's poses; no track ids."""
    names = SourceFrames.of(spec, sequences)
    frames = []
    for s, seq in enumerate(sequences):
        rec = records[seq.name]
        for t in range(len(seq)):
            d = rec[t]
            frames.append(
                PredictedFrame(
                    names.tokens[s][t],
                    float(seq.timestamps[t]),
                    seq.name,
                    np.asarray(d.classes, np.int64),
                    np.asarray(d.scores, np.float32),
                    np.asarray(d.points, np.float32),
                    np.asarray(seq.poses[t], np.float64),
                    None,
                    None if d.queries is None else np.asarray(d.queries, np.float32),
                )  # fmt: skip
            )
    meta = {"method": method, "source": spec}
    return PredictionSet("icmapper", "", frames, range_name, "ego", meta)


def write_predictions(path: str | os.PathLike, preds: PredictionSet, format: str) -> Path:
    """Writes ``preds`` as ``format`` (atomically); ValueError for a format icmapper only
    reads."""
    fmt = get_format(format)
    if fmt.write is None:
        raise ValueError(f"prediction format {format!r} can be read but not written")
    out = Path(path)
    fmt.write(out, preds)
    return out


def export_run(
    run_dir: str | os.PathLike,
    out: str | os.PathLike,
    format: str = "icmapper",
    sequences: list[Sequence] | None = None,
) -> Path:
    """Writes a run folder's per-frame predictions to ``out`` in ``format``; returns the path."""
    return write_predictions(out, run_predictions(run_dir, sequences), format)
