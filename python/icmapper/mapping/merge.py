"""The merge step of one frame (step 6 of the mapper's pipeline): every tracked detection goes
into the global map by the rule for what it is.

- a crossing whose instance is in the map: the crossing rule (``mapping.crossings``);
- a polyline whose instance is in the map: the stretch the car has not passed yet
  (``mapping.passed``), spliced in when fusion already combined it with the history
  (``mapping.splice``, ``fused_merge = "splice"``), merged by curve fit otherwise (collected and
  run in one parallel ``merge_many`` call: the same map as merging in order);
- a lane-line view that runs beside its instance instead of on it (``beside_gate``,
  ``mapping.passed.lies_beside``) shows another line: its track leaves the instance (an alias is
  dropped, an instance's own track gets a fresh id) and the view goes in as a new instance;
- a new instance: inserted once its track has been seen in ``min_hits`` frames, or at once when
  its detection scores at least ``confirm_score`` (a confident first sighting is not held back:
  an instance in range in a single keyframe would never enter the map) and, for a crossing, the
  view is more than a sliver at the range edge (``CrossingMerger.confirmable``); with
  ``drop_stubs`` a lane-line stub across a longer stored line is not inserted
  (``map_nms.is_stub``).

Rejected geometry is reported to ``on_failure`` and skipped. The map, the crossing rule and the
tracker's points change in place; the caller owns them. No I/O.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from icmapper.data.types import MapClass, ego_to_world
from icmapper.mapping.config import MapperConfig
from icmapper.mapping.crossings import CrossingMerger
from icmapper.mapping.map_nms import is_stub
from icmapper.mapping.passed import fresh_runs, lies_beside
from icmapper.mapping.splice import clip_to_detected, splice_into
from icmapper.mapping.tracker import Tracker

if TYPE_CHECKING:
    from icmapper._icmap import GlobalMap

#: (frame index, global instance id, the error) of a rejected insert or merge.
FailureSink = Callable[[int, int, BaseException], None]


def merge_frame(
    global_map: GlobalMap,
    crossings: CrossingMerger,
    tracker: Tracker,
    alias: dict[int, int],
    config: MapperConfig,
    *,
    classes: NDArray[np.int64],
    scores: NDArray[np.float32],
    track_ids: NDArray[np.int64],
    fused: NDArray[np.float32],
    was_fused: NDArray[np.bool_],
    detected: NDArray[np.float32],
    pose: NDArray[np.float64],
    frame_index: int,
    on_failure: FailureSink,
) -> tuple[list[int], list[int], list[int]]:
    """Merges the m tracked detections of one frame (classes (m,), scores (m,), track ids (m,),
    points ``fused`` (m, P, 2) ego, ``was_fused`` (m,), the points before fusion ``detected`` (m,
    P, 2) ego) at ``pose`` (4, 4) ego->world; ``alias``
    maps a track id to the instance it merges into. Returns the instance ids inserted and merged
    into, and the tracks split off their instance (``beside_gate``: their ids, already in
    ``track_ids``, which changes in place where a track got a fresh id)."""
    inserted: list[int] = []
    merged: list[int] = []
    split: list[int] = []
    # Inserts and crossing merges now (a later detection of this frame may merge into a new
    # instance), polyline merges collected and run in one parallel merge_many call: the same
    # map as merging in order.
    # (track, target, world, the runs of world that merge: mapping.passed)
    merge_items: list[tuple[int, int, NDArray[np.float64], list[NDArray[np.float64]]]] = []

    def commit(
        tid: int, target: int, world: NDArray[np.float64], change: Callable[[], object]
    ) -> None:
        """Runs ``change`` of instance ``target`` now: merged, the track's points follow; or
        rejected (ValueError: degenerate geometry), reported."""
        try:
            change()
        except ValueError as exc:
            on_failure(frame_index, target, exc)
            return
        merged.append(target)
        tracker.set_points(tid, world)

    for j in range(len(track_ids)):
        tid = int(track_ids[j])
        world = ego_to_world(fused[j], pose)  # (P, 2)
        target = alias.get(tid, tid)  # the global instance this track maps into
        crossing = int(classes[j]) == MapClass.PED_CROSSING
        spliced = bool(was_fused[j]) and config.fused_merge == "splice"
        # the view to merge: with fused_clip a spliced view only over the stretch detected
        ego, view = fused[j], world
        if spliced and config.fused_clip:
            ego = clip_to_detected(fused[j], detected[j])  # (P, 2)
            view = ego_to_world(ego, pose)
        if (
            target in global_map
            and int(classes[j]) == MapClass.DIVIDER
            and config.beside_gate > 0
            and lies_beside(view, global_map.get(target)[1], config.beside_gate)
        ):  # another lane line than its instance's: the track becomes a new instance
            alias.pop(tid, None)
            if tid in global_map:
                tid = tracker.split(tid)
                track_ids[j] = tid
            target = tid
            split.append(tid)
        if target in global_map and crossing:  # by the crossing rule (mapping.crossings)
            change = partial(crossings.merge, global_map, target, world, fused[j], frame_index)
            commit(tid, target, world, change)
            continue
        if target in global_map:
            # not the stretch the car has passed (mapping.passed); the tracker keeps it all
            stored = global_map.get(target)[1]
            if not spliced:
                runs = fresh_runs(fused[j], world, stored, config.merge_behind)
                merge_items.append((tid, target, world, runs))
                continue
            # the fusion already combined it with the history (mapping.splice); with fused_clip
            # only the stretch the detection covers merges
            runs = fresh_runs(ego, view, stored, config.merge_behind)
            change = partial(
                _splice_runs, global_map, target, runs, config.splice_overlap, frame_index
            )
            commit(tid, target, world, change)
            continue
        # a tentative track stays out of the map until confirmed, unless its sighting is
        # confident: a crossing then only when more than a sliver at the range edge
        tentative = tracker.track(tid).hits < config.min_hits
        if tentative and not (
            scores[j] >= config.confirm_score and (not crossing or crossings.confirmable(fused[j]))
        ):
            continue
        if (
            config.drop_stubs
            and int(classes[j]) == MapClass.DIVIDER
            and is_stub(global_map, world, config.stub_length, config.stub_angle)
        ):  # a stub across the lanes: lane lines do not cross (mapping.map_nms)
            continue
        try:
            global_map.insert_with_id(tid, int(classes[j]), world, frame=frame_index)
        except ValueError as exc:  # degenerate geometry (e.g. a collapsed detection)
            on_failure(frame_index, target, exc)
            continue
        if crossing:
            crossings.inserted(tid, fused[j])
        inserted.append(tid)
        tracker.set_points(tid, world)
    if merge_items:  # one item per run, the runs of a track in order
        flat = [(target, run) for _, target, _, runs in merge_items for run in runs]
        ids, runs_ = [t for t, _ in flat], [r for _, r in flat]
        errors = iter(global_map.merge_many(ids, runs_, frame=frame_index) if flat else ())
        for tid, target, world, runs in merge_items:
            failed = [exc for exc in (next(errors) for _ in runs) if exc is not None]
            if failed:
                on_failure(frame_index, target, failed[0])
                continue
            merged.append(target)
            tracker.set_points(tid, world)
    return inserted, merged, split


def _splice_runs(
    global_map: GlobalMap,
    target: int,
    runs: list[NDArray[np.float64]],
    overlap: float,
    frame_index: int,
) -> None:
    """Splices the runs of one view into ``target`` in order (``mapping.splice``)."""
    for run in runs:
        splice_into(global_map, target, run, overlap, frame_index)
