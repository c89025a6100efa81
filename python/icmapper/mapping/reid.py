"""Re-identification of new tracks against the global map (an extension of IC-Mapper, documented
in docs/mapping.md): a new track at least ``reid_overlap`` of whose points lie within
``reid_distance`` of a same-class global instance takes that instance's id, so that a lost and
re-found track does not duplicate the map. Pure geometry on the sampled history; no state.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from icmapper.geom import point_to_segments, polyline_segments


@dataclass
class ReidDecision:
    """What re-identification decided for one frame: ``renamed`` track id -> global id (the track
    takes the instance's id), ``aliased`` track id -> global id (another piece of an instance
    already matched this frame: the track keeps its id and maps into the instance)."""

    renamed: dict[int, int] = field(default_factory=dict)
    aliased: dict[int, int] = field(default_factory=dict)


def reidentify(
    det_classes: NDArray[np.int64],
    det_points: NDArray[np.float32],
    track_ids: NDArray[np.int64],
    is_new: NDArray[np.bool_],
    hist_row: dict[int, int],
    hist_cls: NDArray[np.int64],
    hist_pts: NDArray[np.float32],
    limit: float,
    min_overlap: float,
) -> ReidDecision:
    """Decides which new tracks lie on a same-class global instance of the sampled history.

    det_classes (k,), det_points (k, P, 2) ego metres, track_ids (k,) the tracker's ids,
    is_new (k,) True where the track is neither in the map nor aliased yet; hist_row: global id
    -> row of the sampled history (hist_cls (h,), hist_pts (h, S, 2) ego metres); limit: metres;
    min_overlap: the share of a track's points that must lie within ``limit`` of the instance.
    """
    out = ReidDecision()
    if limit <= 0 or not hist_row:
        return out
    taken = {int(i) for i in track_ids if int(i) in hist_row}
    for j, tid in enumerate(track_ids.tolist()):
        if not is_new[j] or tid in hist_row:
            continue  # an existing instance: nothing to re-identify
        cls = int(det_classes[j])
        cands = [(gid, row) for gid, row in hist_row.items() if int(hist_cls[row]) == cls]
        if not cands:
            continue
        hist = hist_pts[[r for _, r in cands]].astype(np.float64)  # (c, S, 2)
        segs = polyline_segments(hist, cls == 0)  # (c, S, 2, 2)
        p = det_points[j][None].astype(np.float64)  # (1, P, 2)
        dist = point_to_segments(p, segs)[0]  # (c, P)
        # share of the detection lying on the instance: a piece that slid along the instance or
        # grew at the range edge still overlaps it over most of its length
        overlap = (dist <= limit).mean(axis=1)  # (c,)
        best = int(np.argmax(overlap - 1e-3 * dist.mean(axis=1)))
        if overlap[best] < min_overlap:
            continue
        gid = cands[best][0]
        if gid in taken:
            out.aliased[tid] = gid
        else:
            out.renamed[tid] = gid
            taken.add(gid)
    return out


def instance_ids(track_ids: NDArray[np.int64], alias: dict[int, int]) -> NDArray[np.int64]:
    """The identity each of a frame's tracks (k,) reports: the global instance it maps into
    (``alias``: a re-identified second piece, an absorbed instance's track), so that a piece joined
    to an instance keeps the instance's identity across frames. Ids stay unique in the frame: a
    track that is its own instance keeps its id, and a second track mapping into an instance
    already reported this frame keeps its own. -> (k,) int64."""
    ids = np.asarray(track_ids, dtype=np.int64)
    owners = {int(t) for t in ids.tolist() if int(t) not in alias}
    out = ids.copy()
    used: set[int] = set()
    for j, t in enumerate(ids.tolist()):
        target = alias.get(int(t))
        if target is not None and target not in owners and target not in used:
            out[j] = target
            used.add(target)
    return out
