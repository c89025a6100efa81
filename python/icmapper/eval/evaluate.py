"""Evaluation entry points: ``evaluate`` (plain containers) and ``evaluate_run`` (a run folder).

``evaluate_run`` reads the run, recomputes the ground truth from the run's source spec
(``icmapper.data``), checks that the run's frames are the source's, and calls ``evaluate``.
The result dict's keys are documented in docs/eval.md.
"""

from __future__ import annotations

import os
from collections.abc import Sequence as Seq
from typing import Any

import numpy as np
from numpy.typing import NDArray

from icmapper.eval.consistency import consistency_map
from icmapper.eval.detection import THRESHOLDS, detection_ap, match
from icmapper.eval.fragmentation import fragmentation
from icmapper.eval.globalmap import CD_CAP, CD_STEP, global_metrics, load_global_map
from icmapper.eval.instances import Instances
from icmapper.eval.runfmt import FramePredictions, Run, RunFormatError, read_run
from icmapper.eval.tracking import DEFAULT_SCORE_THRESHOLD, GATES, tracking_metrics

RESULT_FORMAT = "icmapper-eval"
RESULT_VERSION = 1


def _frame_points(points: Any, k: int, where: str) -> NDArray[np.float64] | None:
    """A frame's points as (k, n, 2) float64, or None for a frame without instances (k = 0)."""
    pts = np.asarray(points, dtype=np.float64)
    if k == 0:
        if pts.size:
            raise ValueError(f"{where}: no instances but points of shape {pts.shape}")
        return None
    if pts.size == 0 or pts.size % (2 * k) or (pts.ndim == 3 and pts.shape[0] != k):
        raise ValueError(f"{where}: {k} instances but points of shape {pts.shape}")
    return pts.reshape(k, -1, 2)


def _table(rows: list[tuple[int, int, Any, Any, Any, Any]], what: str) -> Instances:
    """Rows (seq, frame, classes (k,), ids (k,), scores (k,), points) -> one table; frames
    without instances give no rows."""
    parts: list[Instances] = []
    n_points: int | None = None
    for s, t, classes, ids, scores, points in rows:
        k = int(np.asarray(ids).shape[0])
        pts = _frame_points(points, k, f"{what} of sequence {s}, frame {t}")
        if pts is None:
            continue
        if n_points is not None and pts.shape[1] != n_points:
            raise ValueError(
                f"{what} of sequence {s}, frame {t}: {pts.shape[1]} points per instance, "
                f"earlier frames have {n_points}"
            )
        n_points = pts.shape[1]
        parts.append(Instances.of_frame(s, t, classes, ids, scores, pts))
    return Instances.concat(parts)


def _pred_table(predictions_per_seq: Seq[Seq[FramePredictions]]) -> Instances:
    rows = [
        (s, t, fp.classes, fp.track_ids, fp.scores, fp.points)
        for s, frames in enumerate(predictions_per_seq)
        for t, fp in enumerate(frames)
    ]
    return _table(rows, "predictions")


def _gt_table(gt_per_seq: Seq[Seq[Any]]) -> Instances:
    """gt_per_seq[s][t]: a FrameGT-like object (ids (k,), classes (k,), points (k, n, 2))."""
    rows = [
        (s, t, g.classes, g.ids, np.ones(np.asarray(g.ids).shape[0]), g.points)
        for s, frames in enumerate(gt_per_seq)
        for t, g in enumerate(frames)
    ]
    return _table(rows, "ground truth")


def _as_global(items: Seq[Any], scored: bool) -> list[tuple]:
    """MapInstance-likes or tuples -> (cls, points, closed[, score])."""
    out = []
    for it in items:
        if isinstance(it, tuple):
            out.append(it if scored or len(it) == 3 else it[:3])
            if scored and len(it) == 3:
                out[-1] = (*it, 1.0)
        else:
            t = (int(it.cls), np.asarray(it.points, dtype=np.float64), bool(it.closed))
            out.append((*t, 1.0) if scored else t)
    return out


def evaluate(
    predictions_per_seq: Seq[Seq[FramePredictions]],
    gt_per_seq: Seq[Seq[Any]],
    global_pred: Seq[Seq[Any] | None] | None = None,
    global_gt: Seq[Seq[Any]] | None = None,
    range_name: str = "60x30",
    score_threshold: float = DEFAULT_SCORE_THRESHOLD,
    gate: float | None = None,
    maptracker: bool = False,
) -> dict:
    """All metrics of one method at one perception range.

    predictions_per_seq[s][t]: FramePredictions of frame t of sequence s (ego frame);
    gt_per_seq[s][t]: FrameGT-like (ids, classes, points (k, 20, 2) ego) of the same frame;
    global_pred[s]: the predicted global map as (cls, points (n, 2) world, closed, score) tuples
    (or None when the sequence has none); global_gt[s]: GT global instances (MapInstance or
    (cls, points, closed)). Mapping metrics are computed when every sequence has both.
    maptracker: also MapTracker's C-mAP (``consistency_maptracker``; needs every frame's pose),
    under the result key "consistency_maptracker".
    Returns the result dict (docs/eval.md, "JSON keys").
    """
    if range_name not in THRESHOLDS:
        raise ValueError(
            f"no evaluation protocol for range {range_name!r}; known: {list(THRESHOLDS)}"
        )
    if len(predictions_per_seq) != len(gt_per_seq):
        raise ValueError(f"{len(predictions_per_seq)} predicted sequences, {len(gt_per_seq)} GT")
    for s, (p, g) in enumerate(zip(predictions_per_seq, gt_per_seq, strict=True)):
        if len(p) != len(g):
            raise ValueError(f"sequence {s}: {len(p)} predicted frames, {len(g)} GT frames")
    thresholds = THRESHOLDS[range_name]
    gate = GATES[range_name] if gate is None else float(gate)
    pred, gt = _pred_table(predictions_per_seq), _gt_table(gt_per_seq)
    m = match(pred, gt, max(max(thresholds), gate))
    det = detection_ap(pred, gt, thresholds, m)
    cons = consistency_map(pred, gt, thresholds, m)
    trk = tracking_metrics(pred, gt, gate, len(gt_per_seq), score_threshold, m)
    result: dict[str, Any] = {
        "format": RESULT_FORMAT,
        "version": RESULT_VERSION,
        "range": range_name,
        "num_sequences": len(gt_per_seq),
        "num_frames": int(sum(len(g) for g in gt_per_seq)),
        "num_predictions": len(pred),
        "num_gt": len(gt),
        "detection": det,
        "consistency": cons,
        "tracking": trk,
        "mapping": None,
    }
    if maptracker:
        from icmapper.data.types import PerceptionRange
        from icmapper.eval.consistency_maptracker import maptracker_cmap

        rng = PerceptionRange.from_name(range_name)
        result["consistency_maptracker"] = maptracker_cmap(
            predictions_per_seq, gt_per_seq, thresholds, (rng.half_x, rng.half_y)
        )
    if global_pred is not None and global_gt is not None:
        if all(g is not None for g in global_pred):
            gp = [_as_global(g, scored=True) for g in global_pred]  # type: ignore[arg-type]
            gg = [_as_global(g, scored=False) for g in global_gt]
            result["mapping"] = global_metrics(gp, gg, thresholds, CD_STEP, CD_CAP)
            result["mapping"]["fragmentation"] = fragmentation(gp, gg)
    return result


def check_run_frames(run: Run, sequences: Seq[Any]) -> list[Any]:
    """Pairs the run's sequences with the source's by name and checks frames and poses.

    Returns the source Sequence of every run sequence, in run order. RunFormatError names the
    file and frame that do not match.
    """
    by_name = {s.name: s for s in sequences}
    out = []
    for rs in run.sequences:
        where = run.path / f"{rs.name}.npz"
        if rs.name not in by_name:
            raise RunFormatError(f"{where}: sequence {rs.name!r} is not in source {run.source!r}")
        seq = by_name[rs.name]
        if len(rs) != len(seq):
            raise RunFormatError(f"{where}: {len(rs)} frames, the source sequence has {len(seq)}")
        bad = np.flatnonzero(rs.frame_index != np.arange(len(seq)))
        if bad.size:
            raise RunFormatError(
                f"{where}: frame {int(bad[0])} has frame_index {int(rs.frame_index[bad[0]])}, "
                f"expected {int(bad[0])} (a run covers every frame of the source, in order)"
            )
        dpos = np.abs(rs.poses - np.asarray(seq.poses)).reshape(len(seq), -1).max(axis=1)
        bad = np.flatnonzero(dpos > 1e-4)
        if bad.size:
            raise RunFormatError(
                f"{where}: frame {int(bad[0])}: pose differs from the source by {dpos[bad[0]]:.3g}"
            )
        out.append(seq)
    return out


def evaluate_run(
    run_dir: str | os.PathLike,
    score_threshold: float = DEFAULT_SCORE_THRESHOLD,
    sources: Seq[Any] | None = None,
    maptracker: bool = False,
) -> dict:
    """Reads a run folder, recomputes ground truth from its source spec and evaluates it.

    sources: the source's sequences when already opened (else ``open_source(run.source)``).
    Mapping metrics need every sequence's global map file and the engine to read it.
    maptracker: also MapTracker's C-mAP (see ``evaluate``).
    """
    from icmapper.data import gt as gt_mod
    from icmapper.data.types import PerceptionRange

    run = read_run(run_dir)
    rng = PerceptionRange.from_name(run.range_name)
    if sources is None:
        from icmapper.data.sources import open_source

        sources = open_source(run.source, render=False)
    seqs = check_run_frames(run, sources)
    preds = [[rs.frame(t) for t in range(len(rs))] for rs in run.sequences]
    gts = [gt_mod.sequence_gt(seq, rng) for seq in seqs]
    have_maps = all(rs.global_map_path is not None for rs in run.sequences)
    global_pred = global_gt = None
    if have_maps and run.sequences:
        global_pred = [load_global_map(rs.global_map_path) for rs in run.sequences]  # type: ignore[arg-type]
        global_gt = [gt_mod.global_gt(seq, rng) for seq in seqs]
    result = evaluate(
        preds, gts, global_pred, global_gt, run.range_name, score_threshold, maptracker=maptracker
    )
    result["method"] = run.method
    result["run"] = str(run.path)
    result["source"] = run.source
    return result


def evaluate_predictions(
    detections: str,
    source: str,
    score_threshold: float = DEFAULT_SCORE_THRESHOLD,
    sources: Seq[Any] | None = None,
    maptracker: bool = False,
) -> dict:
    """Evaluates a prediction file (``--detections file:PATH[:FORMAT][:RANGE]`` syntax) on the
    sequences of ``source`` like a run without global maps: per-frame metrics only. Track ids are
    the file's where it has them; otherwise every prediction gets its own id (tracking and
    icmapper's C-mAP then say nothing; MapTracker's C-mAP re-derives ids).
    """
    from icmapper.data import gt as gt_mod
    from icmapper.formats.source import PredictionInput
    from icmapper.mapping.run import DetectionInput, unique_track_ids

    if not detections.startswith("file:"):
        raise ValueError(f"expected file:PATH[:FORMAT][:RANGE], got {detections!r}")
    inp = DetectionInput.parse(detections, None)
    preds = inp.predictions
    from icmapper.data.types import PerceptionRange

    rng = PerceptionRange.from_name(preds.range_name)
    if sources is None:
        from icmapper.data.sources import open_source

        sources = open_source(source, render=False)
    seqs = list(sources)
    matched = PredictionInput(preds, source, seqs)
    per_seq = []
    fresh = 1 << 50
    for seq in seqs:
        frames = []
        for t, f in enumerate(matched.frames(seq)):
            ids = f.track_ids if f.track_ids is not None else np.full(len(f), -1, np.int64)
            ids, fresh = unique_track_ids(ids, fresh)
            frames.append(
                FramePredictions(
                    t,
                    np.asarray(seq.poses[t], np.float64),
                    f.classes,
                    f.scores.astype(np.float64),
                    f.points,
                    ids,
                    float(seq.timestamps[t]),
                )  # fmt: skip
            )
        per_seq.append(frames)
    gts = [gt_mod.sequence_gt(seq, rng) for seq in seqs]
    result = evaluate(
        per_seq, gts, None, None, preds.range_name, score_threshold, maptracker=maptracker
    )
    if all(f.track_ids is None for f in preds.frames):  # id-based numbers would mean nothing
        from icmapper.eval.untracked import without_track_ids

        without_track_ids(result)
    result["method"] = f"{preds.format}:{os.path.basename(preds.path)}"
    result["run"] = preds.path
    result["source"] = source
    return result
