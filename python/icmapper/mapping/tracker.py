"""Inference-time association: matching detections to tracked instances and keeping the tracking
buffer (IC-Mapper Fig. 2, "inference association").

The tracker is generic over an affinity matrix: the learned association network (IC-Mapper), or
`positional_affinity` (Chamfer distance; Post-Track and the oracle source, which has no query
features). Per frame: pairs with score >= threshold and the same class are candidates, a one-to-one
assignment maximises the summed score (Hungarian), unmatched detections open new tracks with fresh
ids (a counter owned by the Tracker instance), matched tracks take the detection's geometry, and
tracks not seen for more than ``max_age`` frames are dropped.

The buffer keeps geometry in the WORLD frame, so that it can be shown to the association network in
any later ego frame (`Tracker.tracks_in_ego`). This module holds no network and no I/O.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from icmapper.data.types import ego_to_world, world_to_ego
from icmapper.geom import point_to_segments, polyline_segments

#: Default length scale (metres) of `positional_affinity`: exp(-chamfer / scale).
DEFAULT_AFFINITY_SCALE = 1.0


@dataclass
class Track:
    """One entry of the tracking buffer.

    id: track id; cls: class index; points (n, 2) float64 WORLD frame (the last geometry seen);
    query (D,) float32 decoder feature of the last detection (None when the detector has none);
    age: frames since last seen (0: seen this frame); hits: frames seen in total.
    """

    id: int
    cls: int
    points: NDArray[np.float64]
    query: NDArray[np.float32] | None
    age: int = 0
    hits: int = 1


def polyline_chamfer_matrix(
    a: NDArray[np.floating],
    b: NDArray[np.floating],
    a_closed: NDArray[np.bool_],
    b_closed: NDArray[np.bool_],
    reduce: str = "mean",
) -> NDArray[np.float64]:
    """Pairwise Chamfer distance between polylines/rings, measured to the lines, not the vertices:
    (mean over a's points of the distance to b's segments + the same from b to a) / 2.
    ``reduce="min"`` takes the smaller of the two directed distances instead: ~0 when one instance
    covers part of the other (an instance that grows or shrinks at the edge of the range).

    a (A, n, 2), b (B, m, 2), a_closed (A,), b_closed (B,) (rings get their closing segment) ->
    (A, B) float64. Unlike the point-to-point Chamfer, two samplings of the same line score ~0
    however sparse they are (20 points over 60 m are 3 m apart).
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.ndim != 3 or a.shape[2] != 2 or b.ndim != 3 or b.shape[2] != 2:
        raise ValueError(
            f"polyline_chamfer_matrix: expected (A, n, 2), (B, m, 2), got {a.shape}, {b.shape}"
        )
    if a.shape[0] == 0 or b.shape[0] == 0:
        return np.zeros((a.shape[0], b.shape[0]), np.float64)
    ab, ba = _point_distances(a, b, a_closed, b_closed)
    return _reduce(ab.mean(axis=2), ba.mean(axis=2), reduce)


def _point_distances(
    a: NDArray[np.float64],
    b: NDArray[np.float64],
    a_closed: NDArray[np.bool_],
    b_closed: NDArray[np.bool_],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The distance of each of a's points to each of b's lines (A, B, n) and of each of b's
    points to each of a's lines (B, A, m); a (A, n, 2), b (B, m, 2) float64."""
    sa = polyline_segments(a, np.asarray(a_closed, bool))  # (A, n, 2, 2)
    sb = polyline_segments(b, np.asarray(b_closed, bool))  # (B, m, 2, 2)
    return point_to_segments(a, sb), point_to_segments(b, sa)


def _reduce(ab: NDArray[np.float64], ba: NDArray[np.float64], reduce: str) -> NDArray[np.float64]:
    """(A, B) from the directed means ab (A, B) and ba (B, A): their mean, or the smaller."""
    if reduce == "min":
        return np.minimum(ab, ba.T)
    return 0.5 * (ab + ba.T)


def same_class_distances(
    det_points: NDArray[np.floating],
    det_classes: NDArray[np.integer],
    trk_points: NDArray[np.floating],
    trk_classes: NDArray[np.integer],
) -> Iterator[
    tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]
]:
    """Per class present on both sides: the detections' and tracks' rows (k_c,), (t_c,) and
    the point distances between them (``_point_distances``: (k_c, t_c, n), (t_c, k_c, m);
    crossings, class 0, as rings)."""
    det_classes, trk_classes = np.asarray(det_classes), np.asarray(trk_classes)
    det_points = np.asarray(det_points, np.float64)
    trk_points = np.asarray(trk_points, np.float64)
    if det_points.shape[:1] != det_classes.shape or trk_points.shape[:1] != trk_classes.shape:
        raise ValueError(
            f"positional_affinity: points {det_points.shape} / classes {det_classes.shape}, "
            f"points {trk_points.shape} / classes {trk_classes.shape} disagree"
        )
    for c in np.intersect1d(det_classes, trk_classes):  # only same-class pairs are computed
        di, ti = np.nonzero(det_classes == c)[0], np.nonzero(trk_classes == c)[0]
        closed_d, closed_t = np.full(len(di), c == 0), np.full(len(ti), c == 0)
        yield di, ti, *_point_distances(det_points[di], trk_points[ti], closed_d, closed_t)


def positional_affinity(
    det_points: NDArray[np.floating],
    det_classes: NDArray[np.integer],
    trk_points: NDArray[np.floating],
    trk_classes: NDArray[np.integer],
    scale: float = DEFAULT_AFFINITY_SCALE,
    reduce: str = "mean",
) -> NDArray[np.float64]:
    """Association scores from geometry alone: exp(-chamfer / scale), 0 across classes.

    det_points (k, n, 2), det_classes (k,), trk_points (t, m, 2), trk_classes (t,), all in the same
    (ego) frame -> (k, t) float64 in [0, 1]. The Chamfer distance is measured to the polylines
    (`polyline_chamfer_matrix`; crossings, class 0, as rings). A Chamfer gate of g metres is the
    score threshold exp(-g / scale). ``reduce``: see `polyline_chamfer_matrix`.
    """
    check_positional(scale, reduce)
    aff = np.zeros((len(det_classes), len(trk_classes)), np.float64)  # (k, t)
    for di, ti, ab, ba in same_class_distances(det_points, det_classes, trk_points, trk_classes):
        aff[np.ix_(di, ti)] = affinity_of(ab, ba, scale, reduce)
    return aff


def check_positional(scale: float, reduce: str) -> None:
    """ValueError for a ``reduce`` other than "mean" / "min" or a ``scale`` not > 0."""
    if reduce not in ("mean", "min"):
        raise ValueError(f"positional_affinity: reduce must be 'mean' or 'min', got {reduce!r}")
    if not scale > 0:
        raise ValueError(f"positional_affinity: scale must be > 0, got {scale}")


def affinity_of(
    ab: NDArray[np.float64], ba: NDArray[np.float64], scale: float, reduce: str
) -> NDArray[np.float64]:
    """(k_c, t_c) `positional_affinity` from the point distances of `same_class_distances`."""
    return np.exp(-_reduce(ab.mean(axis=2), ba.mean(axis=2), reduce) / scale)


def shared_of(ab: NDArray[np.float64], ba: NDArray[np.float64], gate: float) -> NDArray[np.float64]:
    """(k_c, t_c) `overlap` from the point distances of `same_class_distances`."""
    return np.minimum((ab <= gate).mean(axis=2), (ba <= gate).mean(axis=2).T)


def match_scores(
    scores: NDArray[np.floating],
    det_classes: NDArray[np.integer],
    trk_classes: NDArray[np.integer],
    threshold: float,
    weights: NDArray[np.floating] | None = None,
) -> NDArray[np.int64]:
    """One-to-one assignment maximising the summed score over admissible pairs.

    scores (k, t) in [0, 1]; a pair is admissible when score >= threshold and the classes agree.
    weights (k, t) >= 0: what the assignment maximises over the admissible pairs instead of the
    scores (``Tracker.assign``'s weighing by ``overlap``). Returns (k,) int64: the matched
    column of each detection, -1 where unmatched.
    """
    scores = np.asarray(scores, dtype=np.float64)
    det_classes = np.asarray(det_classes, dtype=np.int64)
    trk_classes = np.asarray(trk_classes, dtype=np.int64)
    k, t = det_classes.shape[0], trk_classes.shape[0]
    if scores.shape != (k, t):
        raise ValueError(
            f"association scores must be ({k}, {t}) (detections, tracks), got {scores.shape}"
        )
    if not np.all(np.isfinite(scores)):
        raise ValueError("association scores contain NaN or inf")
    if scores.size and (scores.min() < 0.0 or scores.max() > 1.0):
        raise ValueError(
            f"association scores must lie in [0, 1], got [{scores.min()}, {scores.max()}]"
        )
    out = np.full(k, -1, np.int64)
    if k == 0 or t == 0:
        return out
    ok = (scores >= threshold) & (det_classes[:, None] == trk_classes[None, :])  # (k, t)
    # Inadmissible pairs weigh 0: scores are >= 0, so the best full assignment restricted to its
    # admissible pairs is a best admissible matching (and vice versa).
    if weights is not None and np.shape(weights) != (k, t):
        raise ValueError(f"association weights must be ({k}, {t}), got {np.shape(weights)}")
    weight = np.where(ok, scores if weights is None else weights, 0.0)  # (k, t)
    rows, cols = linear_sum_assignment(weight, maximize=True)
    keep = ok[rows, cols]
    out[rows[keep]] = cols[keep]
    return out


#: The weight an admissible pair keeps however little its detection and track share.
COVER_FLOOR = 0.05


def overlap(
    det_points: NDArray[np.floating],
    det_classes: NDArray[np.integer],
    trk_points: NDArray[np.floating],
    trk_classes: NDArray[np.integer],
    gate: float,
) -> NDArray[np.float64]:
    """(k, t): how much of each detection (k, n, 2) and each track's view (t, n, 2) lie on each
    other, both in one frame: the smaller of the share of the track's points within ``gate``
    metres of the detection's polyline and the share of the detection's points within it of the
    track's (crossings, class 0, as rings): about the length they share over the longer one's.
    0 across classes."""
    out = np.zeros((len(det_classes), len(trk_classes)), np.float64)  # (k, t)
    for di, ti, ab, ba in same_class_distances(det_points, det_classes, trk_points, trk_classes):
        out[np.ix_(di, ti)] = shared_of(ab, ba, gate)
    return out


class Tracker:
    """Inference association with a tracking buffer (state lives in the instance, no globals).

    threshold: minimum score θ of an accepted match; max_age: a track unseen for more than this many
    consecutive frames is dropped (0: tracks live one frame only).
    """

    def __init__(self, threshold: float = 0.5, max_age: int = 3) -> None:
        if not 0.0 <= threshold <= 1.0:
            raise ValueError(f"Tracker: threshold must be in [0, 1], got {threshold}")
        if max_age < 0:
            raise ValueError(f"Tracker: max_age must be >= 0, got {max_age}")
        self.threshold = float(threshold)
        self.max_age = int(max_age)
        self._tracks: list[Track] = []
        self._next_id = 0

    def reset(self) -> None:
        """Forgets every track and restarts ids at 0 (a new sequence)."""
        self._tracks = []
        self._next_id = 0

    @property
    def tracks(self) -> list[Track]:
        """The buffer, in the column order of the score matrices (`tracks_in_ego`, `assign`)."""
        return list(self._tracks)

    def __len__(self) -> int:
        return len(self._tracks)

    def track(self, track_id: int) -> Track:
        """The buffer entry of `track_id` (KeyError if not tracked)."""
        for tr in self._tracks:
            if tr.id == track_id:
                return tr
        raise KeyError(f"track {track_id} is not in the buffer")

    def tracks_in_ego(
        self, pose: NDArray[np.float64]
    ) -> tuple[
        NDArray[np.int64], NDArray[np.int64], NDArray[np.float32], NDArray[np.float32] | None
    ]:
        """The buffer seen from the ego pose (4, 4) ego->world, for the association network.

        Returns ids (t,) int64, classes (t,) int64, points (t, n, 2) float32 EGO frame (n = the
        detections' point count, 20), queries (t, D) float32 or None when any track lacks a query.
        """
        t = len(self._tracks)
        ids = np.array([tr.id for tr in self._tracks], np.int64)  # (t,)
        classes = np.array([tr.cls for tr in self._tracks], np.int64)  # (t,)
        if t == 0:
            return ids, classes, np.zeros((0, 20, 2), np.float32), None
        pose = np.asarray(pose, dtype=np.float64)
        pts = np.stack([world_to_ego(tr.points, pose) for tr in self._tracks]).astype(np.float32)
        if any(tr.query is None for tr in self._tracks):
            queries = None
        else:
            queries = np.stack([tr.query for tr in self._tracks]).astype(np.float32)  # (t, D)
        return ids, classes, pts, queries  # pts (t, n, 2)

    def assign(
        self,
        scores: NDArray[np.floating],
        det_classes: NDArray[np.integer],
        det_points: NDArray[np.floating],
        pose: NDArray[np.float64],
        det_queries: NDArray[np.floating] | None = None,
        shared: NDArray[np.floating] | None = None,
    ) -> NDArray[np.int64]:
        """Associates one frame's detections with the buffer and updates it.

        scores (k, t) in [0, 1] against `tracks` in order; det_classes (k,); det_points (k, n, 2)
        EGO frame; pose (4, 4) ego->world; det_queries (k, D) or None; shared (k, t) or None: how
        much each detection and track share (`overlap`), to weigh the admissible pairs by
        (score x (``COVER_FLOOR`` + shared)): where the range edge cuts a track's line into a
        long piece and a corner piece, both lie on the track and the long one continues it; a
        short piece lying on a long line takes the short track, not the long one. Returns the
        track id of each detection (k,) int64 (fresh, increasing ids for unmatched detections).
        Matched tracks take the detection's geometry (world frame) and query; tracks unseen for
        more than max_age frames are dropped. On bad input nothing changes (ValueError).
        """
        det_classes = np.asarray(det_classes, dtype=np.int64)
        det_points = np.asarray(det_points, dtype=np.float64)
        pose = np.asarray(pose, dtype=np.float64)
        k = det_classes.shape[0]
        if det_points.ndim != 3 or det_points.shape[0] != k or det_points.shape[2] != 2:
            raise ValueError(
                f"Tracker.assign: det_points must be ({k}, n, 2), got {det_points.shape}"
            )
        if not np.all(np.isfinite(det_points)):
            raise ValueError("Tracker.assign: det_points contain NaN or inf")
        if pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
            raise ValueError(
                f"Tracker.assign: pose must be a finite (4, 4) matrix, got {pose.shape}"
            )
        if det_queries is not None:
            det_queries = np.asarray(det_queries, dtype=np.float32)
            if det_queries.ndim != 2 or det_queries.shape[0] != k:
                raise ValueError(
                    f"Tracker.assign: det_queries must be ({k}, D), got {det_queries.shape}"
                )
        trk_classes = np.array([tr.cls for tr in self._tracks], np.int64)  # (t,)
        weights = None
        if shared is not None:
            weights = np.asarray(scores, np.float64) * (COVER_FLOOR + np.asarray(shared))  # (k, t)
        cols = match_scores(scores, det_classes, trk_classes, self.threshold, weights)  # (k,)

        ids = np.empty(k, np.int64)
        seen: set[int] = set()
        new_tracks: list[Track] = []
        for i in range(k):
            pts_w = ego_to_world(det_points[i], pose)  # (n, 2)
            q = None if det_queries is None else det_queries[i].copy()
            if cols[i] >= 0:
                tr = self._tracks[int(cols[i])]
                tr.points, tr.query, tr.age = pts_w, q, 0
                tr.hits += 1
            else:
                tr = Track(self._next_id, int(det_classes[i]), pts_w, q)
                self._next_id += 1
                new_tracks.append(tr)
            ids[i] = tr.id
            seen.add(tr.id)
        kept = []
        for tr in self._tracks:
            if tr.id not in seen:
                tr.age += 1
            if tr.age <= self.max_age:
                kept.append(tr)
        self._tracks = kept + new_tracks
        return ids

    @property
    def next_id(self) -> int:
        """The id the next new track will get."""
        return self._next_id

    def reserve_ids(self, below: int) -> None:
        """Makes every future new id >= `below` (continuing an existing map whose ids are used)."""
        self._next_id = max(self._next_id, int(below))

    def restore(self, tracks: list[Track], next_id: int) -> None:
        """Replaces the buffer and the id counter, e.g. with a saved run's (``mapping.state``).
        ValueError, with nothing changed, for duplicate ids, a negative counter, bad geometry,
        negative ages or hits < 1."""
        ids = [int(t.id) for t in tracks]
        if len(set(ids)) != len(ids):
            raise ValueError("Tracker.restore: duplicate track ids")
        if next_id < 0:
            raise ValueError(f"Tracker.restore: next id must be >= 0, got {next_id}")
        for t in tracks:
            pts = np.asarray(t.points)
            if pts.ndim != 2 or pts.shape[1] != 2 or not np.all(np.isfinite(pts)):
                raise ValueError(f"Tracker.restore: track {t.id} needs finite (n, 2) points")
            if t.age < 0 or t.hits < 1:
                raise ValueError(f"Tracker.restore: track {t.id} has age {t.age}, hits {t.hits}")
        self._tracks = list(tracks)
        self._next_id = int(next_id)

    def rename(self, track_id: int, new_id: int) -> None:
        """Gives track `track_id` the id `new_id` (re-identification against the global map); any
        other buffer entry holding `new_id` is dropped."""
        tr = self.track(track_id)
        self._tracks = [t for t in self._tracks if t.id != new_id or t is tr]
        tr.id = int(new_id)

    def split(self, track_id: int) -> int:
        """Gives track `track_id` a fresh id (it follows another line than its instance's: a new
        identity from now on) and returns it."""
        tr = self.track(track_id)
        tr.id = self._next_id
        self._next_id += 1
        return tr.id

    def set_points(self, track_id: int, points_world: NDArray[np.floating]) -> None:
        """Replaces a track's stored geometry (n, 2) WORLD frame, e.g. with the fused result."""
        pts = np.asarray(points_world, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 2 or not np.all(np.isfinite(pts)):
            raise ValueError(f"Tracker.set_points: need finite (n, 2) points, got {pts.shape}")
        self.track(track_id).points = pts.copy()
