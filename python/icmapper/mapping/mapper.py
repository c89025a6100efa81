"""The IC-Mapper online pipeline: detect -> associate -> sample -> fuse -> merge, per frame.

``Mapper`` owns all state of one sequence (detector memory, tracking buffer, global map); two
Mappers run side by side. It runs with the learned networks (``Mapper.from_checkpoint``) or with any
``DetectionSource`` (e.g. the noisy-GT oracle, ``Mapper.with_oracle``), in which case association
falls back to positional affinity and fusion is skipped.

Per frame (paper Fig. 2):
1. detections above ``detect_threshold`` (all of them go to the run for AP);
2. those above ``track_threshold`` are associated with the tracking buffer: learned scores
   ``H`` (or positional affinity without query features), threshold θ, one-to-one assignment
   maximising the summed score; unmatched detections get new ids;
3. re-identification against the map (an extension, documented in docs/mapping.md): a new track
   at least half of whose points lie within ``reid_distance`` of a same-class global instance takes
   that instance's id, so a lost track does not duplicate the map (with ``reid_alias``, a second
   new piece of an instance matched this frame maps into it);
4. the global map is sampled in the patch expanded by ``fusion_margin`` (Rust ``sample_patch``);
5. fusion of every tracked detection with the history of its id;
6. merge into the global map (polylines: a fused one is spliced in, replacing the stretch it
   covers, by ``fused_merge``, since fusion already combined it with the history; an unfused one
   by curve fit; crossings by ``crossing_merge``: the running mean of complete views, union of
   views cut by the range edge that reveal more of a crossing), or insert once the
   track has been seen in ``min_hits`` frames or scores ``confirm_score`` (tentative tracks keep
   one-off false positives out of the map, a confident first sighting goes in; an extension like
   step 3);
7. absorption (``absorb``, an extension): an instance this step inserted or merged into and a
   same-class neighbour it lies on over most of its length become one (``GlobalMap.absorb``); the
   tracks of the absorbed instance map into the kept one. Pieces of one line that the tracker
   kept apart (a skeleton piece, a track found again beside its instance) stop doubling the map.
   Then lane lines do not cross (``drop_stubs``, an extension): a stub across the lanes among
   the dividers the step touched and their neighbours is removed (``map_nms.drop_stubs``).

Steps 6 and 7 are left out while the ego stands still (``min_travel``, an extension): a frame
whose pose lies within ``min_travel`` metres and ``STILL_TURN`` degrees of the last frame that
merged (``data.types.stands_still``) merges nothing (a car stopped at a light sees one view
again and again, and merging it every frame piles that view's errors into the map); its
detections are still tracked, fused and reported.

This module is the pipeline and the state it carries; each step's logic has its own module:
``associate`` (scores; the assignment is ``tracker``'s), ``reid``, ``fuse``, ``merge`` (with the
rules in ``crossings``, ``passed``, ``splice``) and ``absorb``; the counters are in ``stats``, the
variants in ``variants``, saving and resuming in ``state``.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from icmapper.data.types import (
    KEYFRAME_HZ,
    Frame,
    PerceptionRange,
    RANGE_60x30,
    Sequence,
    pose_to_xy_yaw,
    stands_still,
)
from icmapper.mapping import state
from icmapper.mapping.absorb import absorb_touched
from icmapper.mapping.associate import association_scores
from icmapper.mapping.config import MapperConfig
from icmapper.mapping.crossings import CrossingMerger
from icmapper.mapping.fuse import fuse_with_history
from icmapper.mapping.map_nms import drop_stubs
from icmapper.mapping.merge import merge_frame
from icmapper.mapping.network_source import NetworkDetector
from icmapper.mapping.reid import instance_ids, reidentify
from icmapper.mapping.stats import NETWORK_STAGES, STAGES, UNTRACKED_ID_BASE, MapperStats
from icmapper.mapping.tracker import Tracker
from icmapper.mapping.types import Detections, DetectionSource, StepResult
from icmapper.mapping.variants import VARIANTS, Variant, network_settings

if TYPE_CHECKING:
    import torch

    from icmapper._icmap import GlobalMap
    from icmapper.models.association import AssociationHead
    from icmapper.models.fusion import FusionModule

__all__ = [
    "NETWORK_STAGES",
    "STAGES",
    "UNTRACKED_ID_BASE",
    "VARIANTS",
    "Mapper",
    "MapperStats",
    "Variant",
    "network_settings",
]


class Mapper:
    """The online mapper (see the module docstring). Implements ``MappingMethod``."""

    def __init__(
        self,
        source: DetectionSource,
        *,
        association: AssociationHead | None = None,
        fusion: FusionModule | None = None,
        config: MapperConfig | None = None,
        rng: PerceptionRange = RANGE_60x30,
        device: str | torch.device = "cpu",
        name: str = "icmapper",
    ) -> None:
        self.source = source
        self.association = association.eval() if association is not None else None
        self.fusion = fusion.eval() if fusion is not None else None
        self.config = config or MapperConfig()
        self.rng = rng
        self.device = device
        self.name = name
        self.tracker = Tracker(self.config.assoc_threshold, self.config.max_age)
        self.crossings = CrossingMerger(self.config.crossing_merge, rng)
        self._new_map()
        self.stats = MapperStats()
        self._untracked = UNTRACKED_ID_BASE
        self._alias: dict[int, int] = {}  # track id -> global instance id it maps into
        self._merge_pose: tuple[float, float, float] | None = None  # x, y, yaw of the last merge
        self._last_time: float | None = None  # the previous frame's timestamp (seconds)
        self._warned_rate = False

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_checkpoint(
        cls,
        path: str | Path,
        config: MapperConfig | None = None,
        device: str = "cpu",
        variant: str = "full",
    ) -> Mapper:
        """The mapper with the networks of a training checkpoint.

        variant: one of ``VARIANTS`` — "full" (IC-Mapper), "no-fusion" (detector + association),
        "base" (detector, positional association, no fusion: StreamMapNet-like + post tracking),
        "single-frame" (like "base" without temporal memory: MapTR-like). Without a config the
        detection threshold and the ``[mapper]`` settings are the checkpoint's;
        ``fusion_margin`` and ``history_points`` always come from the fusion network (a config
        that sets other values raises ValueError). The learned association and fusion run when
        both the variant and the config use them.
        """
        from icmapper.models.network import load_network

        if variant not in VARIANTS:
            raise ValueError(f"unknown variant {variant!r}; expected one of {sorted(VARIANTS)}")
        loaded = load_network(path, device)
        v = VARIANTS[variant]
        cfg = config or MapperConfig.for_checkpoint(str(path))
        cfg = replace(
            network_settings(cfg, loaded.model.fusion_margin, loaded.model.fusion_history_points),
            # a variant switches a network off; so does the config (`--set use_fusion=false`)
            use_association=v.use_association and cfg.use_association,
            use_fusion=v.use_fusion and cfg.use_fusion,
        )
        name = "icmapper" if variant == "full" else f"icmapper-{variant}"
        return cls(
            NetworkDetector(loaded.net.detector, device, temporal=v.temporal),
            association=loaded.net.association,
            fusion=loaded.net.fusion,
            config=cfg,
            rng=loaded.rng,
            device=device,
            name=name,
        )

    @classmethod
    def with_oracle(
        cls,
        sequence: Sequence,
        noise: Any = "low",
        seed: int = 0,
        config: MapperConfig | None = None,
        rng: PerceptionRange = RANGE_60x30,
    ) -> Mapper:
        """The mapper fed by the noisy-GT oracle (positional association, no fusion)."""
        from icmapper.mapping.oracle import OracleDetector

        return cls(
            OracleDetector(sequence, rng=rng, noise=noise, seed=seed), config=config, rng=rng
        )

    # ------------------------------------------------------------------ state
    def _new_map(self) -> None:
        from icmapper._icmap import GlobalMap

        self._map = GlobalMap(smoothing=self.config.smoothing, spacing=self.config.spacing)
        self.crossings.reset()

    @property
    def global_map(self) -> GlobalMap:
        return self._map

    @property
    def alias(self) -> dict[int, int]:
        """Track id -> the global instance id it maps into (a copy)."""
        return dict(self._alias)

    @property
    def merge_pose(self) -> tuple[float, float, float] | None:
        """The ego's (x, y, yaw) world pose at the last frame that merged (None: none yet)."""
        return self._merge_pose

    @property
    def untracked_next(self) -> int:
        """The id the next reported but untracked detection gets."""
        return self._untracked

    def reset(self) -> None:
        """A new sequence: empty map, empty buffer, detector memory cleared."""
        self.source.reset()
        self.tracker.reset()
        self._new_map()
        self.stats = MapperStats()
        self._untracked = UNTRACKED_ID_BASE
        self._alias = {}
        self._merge_pose = None
        self._last_time = None
        self._warned_rate = False

    def restore(
        self,
        global_map: GlobalMap,
        *,
        alias: dict[int, int],
        untracked: int | None = None,
        stats: MapperStats | None = None,
        crossing_counts: dict[int, int] | None = None,
        merge_pose: tuple[float, float, float] | None = None,
    ) -> None:
        """Replaces the map, the aliases, the crossing rule's view counts (none given: none),
        the pose of the last merge (none: the next frame merges) and (when given) the
        untracked-id counter and the stats: used by ``mapping.state.resume``, which restores the
        tracker and the source itself."""
        self.crossings.reset(crossing_counts)
        self._map = global_map
        self._alias = dict(alias)
        self._merge_pose = merge_pose
        if untracked is not None:
            self._untracked = int(untracked)
        if stats is not None:
            self.stats = stats

    def save_state(self, path: str | Path) -> None:
        """Saves everything the next step depends on (``mapping.state.save_state``)."""
        state.save_state(self, path)

    def resume(self, path: str | Path) -> None:
        """Continues a saved run (``mapping.state.resume``)."""
        state.resume(self, path)

    def finish(self) -> GlobalMap:
        return self._map

    # ------------------------------------------------------------------ one frame
    def step(self, frame: Frame) -> StepResult:
        """Processes one keyframe. Bad input (NaN points, bad pose) raises ValueError before any
        state changes."""
        cfg = self.config
        pose = np.asarray(frame.pose, dtype=np.float64)
        xyyaw = pose_to_xy_yaw(pose)  # validates the pose
        sec = self.stats.seconds
        t0 = time.perf_counter()
        dets = self.source.detect(frame)
        dets.validate()
        dets = _select(dets, dets.scores >= cfg.detect_threshold)
        tracked = dets.scores >= cfg.track_threshold  # (k,)
        det = _select(dets, tracked)
        t1 = time.perf_counter()
        sec["detector"] += t1 - t0

        track_ids = self._associate(det, pose)  # times "association" and "tracking"
        t2 = time.perf_counter()
        hist_ids, hist_cls, hist_pts, _ = self._map.sample_patch(
            xyyaw,
            (self.rng.half_x, self.rng.half_y),
            margin=cfg.fusion_margin,
            n_points=cfg.history_points,
        )
        hist_row = {int(i): j for j, i in enumerate(hist_ids.tolist())}
        t2b = time.perf_counter()
        sec["sampling"] += t2b - t2
        track_ids = self._reidentify(det, track_ids, hist_row, hist_cls, hist_pts)
        t3 = time.perf_counter()
        sec["tracking"] += t3 - t2b
        fused, was_fused = self._fuse(det, track_ids, hist_row, hist_pts)  # (m, P, 2) ego, (m,)
        t4 = time.perf_counter()
        sec["fusion"] += t4 - t3

        inserted: list[int] = []
        merged: list[int] = []
        if stands_still(xyyaw, self._merge_pose, self.config.min_travel):
            self.stats.still += 1
        else:
            inserted, merged = self._merge(det, track_ids, fused, was_fused, pose, frame.index)
            self._absorb(inserted + merged)
            self._merge_pose = xyyaw
        sec["merge"] += time.perf_counter() - t4

        all_ids = np.empty(len(dets), np.int64)
        all_ids[tracked] = instance_ids(track_ids, self._alias)  # what each track maps into
        n_untracked = int((~tracked).sum())
        all_ids[~tracked] = np.arange(self._untracked, self._untracked + n_untracked)
        self._untracked += n_untracked
        points = dets.points.copy()
        points[tracked] = fused
        self.stats.frames += 1
        self._check_rate(float(frame.timestamp))
        return StepResult(frame.index, dets, all_ids, points, inserted, merged)

    def _check_rate(self, t: float) -> None:
        """Warns once per sequence when frames come much faster than ``KEYFRAME_HZ``: the
        detector's temporal memory and the tracker's frame counts were built for keyframes 0.5 s
        apart, and at 10 Hz the maps are far worse (docs/mapping.md, "Keyframes 0.5 s apart")."""
        last, self._last_time = self._last_time, t
        if last is None or self._warned_rate or not 0 < t - last < 0.5 / KEYFRAME_HZ:
            return
        self._warned_rate = True
        warnings.warn(
            f"{self.name}: frames {t - last:.3f} s apart; icmapper maps keyframes "
            f"{1 / KEYFRAME_HZ:g} s apart ({KEYFRAME_HZ:g} Hz), and faster frames make worse "
            "maps: subsample the frames to keyframes (Sequence.keyframes(); docs/mapping.md, "
            "'Keyframes 0.5 s apart')",
            stacklevel=3,
        )

    def _associate(self, det: Detections, pose: NDArray[np.float64]) -> NDArray[np.int64]:
        """Track ids (k,) of the detections: scores against the buffer (``mapping.associate``),
        then the tracker's one-to-one assignment."""
        t0 = time.perf_counter()
        _, trk_cls, trk_pts, trk_q = self.tracker.tracks_in_ego(pose)
        head = self.association if self.config.use_association else None
        detector: Any = getattr(self.source, "detector", None)
        scores, shared = association_scores(
            det,
            trk_cls,
            trk_pts,
            trk_q,
            head=head,
            to_unit=getattr(detector, "to_unit", None),
            device=self.device,
            positional_scale=self.config.positional_scale,
            share_gate=self.config.assign_cover,  # positional scores only: the learned as they are
        )  # (k, t), (k, t) or None
        t1 = time.perf_counter()
        ids = self.tracker.assign(scores, det.classes, det.points, pose, det.queries, shared)
        self.stats.seconds["association"] += t1 - t0
        self.stats.seconds["tracking"] += time.perf_counter() - t1
        return ids

    def _reidentify(
        self,
        det: Detections,
        track_ids: NDArray[np.int64],
        hist_row: dict[int, int],
        hist_cls: NDArray[np.int64],
        hist_pts: NDArray[np.float32],
    ) -> NDArray[np.int64]:
        """New tracks lying on a same-class global instance take its id (``mapping.reid``)."""
        is_new = np.array(
            [t not in self._map and t not in self._alias for t in track_ids.tolist()], bool
        )  # (k,)
        decision = reidentify(
            det.classes,
            det.points,
            track_ids,
            is_new,
            hist_row,
            hist_cls,
            hist_pts,
            self.config.reid_distance,
            self.config.reid_overlap,
        )
        ids = track_ids.copy()
        for j, tid in enumerate(track_ids.tolist()):
            if tid in decision.aliased and self.config.reid_alias:
                self._alias[tid] = decision.aliased[tid]
                self.stats.aliased += 1
            elif tid in decision.renamed:
                self.tracker.rename(tid, decision.renamed[tid])
                ids[j] = decision.renamed[tid]
                self.stats.reidentified += 1
        return ids

    def _fuse(
        self,
        det: Detections,
        track_ids: NDArray[np.int64],
        hist_row: dict[int, int],
        hist_pts: NDArray[np.float32],
    ) -> tuple[NDArray[np.float32], NDArray[np.bool_]]:
        """The fused points (m, P, 2) ego and which detections were fused (m,): those whose
        instance has a history in the map (``mapping.fuse``; the others pass through)."""
        if not (self.config.use_fusion and self.fusion is not None) or len(det) == 0:
            return det.points.copy(), np.zeros(len(det), bool)
        targets = [self._alias.get(int(i), int(i)) for i in track_ids]
        return fuse_with_history(
            det,
            targets,
            hist_row,
            hist_pts,
            self.fusion,
            self.config.history_points,
            self.device,
            classes=self.config.fusion_classes,
        )

    def _merge(
        self,
        det: Detections,
        track_ids: NDArray[np.int64],
        fused: NDArray[np.float32],
        was_fused: NDArray[np.bool_],
        pose: NDArray[np.float64],
        frame_index: int,
    ) -> tuple[list[int], list[int]]:
        """Merges the tracked detections into the map (``mapping.merge``); returns the ids
        inserted and merged into."""
        inserted, merged, split = merge_frame(
            self._map,
            self.crossings,
            self.tracker,
            self._alias,
            self.config,
            classes=det.classes,
            scores=det.scores,
            track_ids=track_ids,
            fused=fused,
            was_fused=was_fused,
            detected=det.points,
            pose=pose,
            frame_index=frame_index,
            on_failure=self.stats.note_failure,
        )
        self.stats.inserted += len(inserted)
        self.stats.merged += len(merged)
        self.stats.split += len(split)
        return inserted, merged

    def _absorb(self, touched: list[int]) -> None:
        """Instances this step inserted or merged into absorb the same-class neighbours they lie
        on, or are absorbed by them (``mapping.absorb``); aliases follow. Then, with
        ``drop_stubs``, the stubs across lanes among them and their neighbours go; a track aliased
        into one maps into its own id again (it re-enters the map only with a view along the
        lanes)."""
        cfg = self.config
        self.stats.absorbed += absorb_touched(self._map, self.crossings, self._alias, cfg, touched)
        if cfg.drop_stubs:  # lane lines do not cross (mapping.map_nms)
            touched = [i for i in touched if i in self._map]
            gone = set(drop_stubs(self._map, touched, cfg.stub_length, cfg.stub_angle))
            for track in [t for t, target in self._alias.items() if target in gone]:
                del self._alias[track]
            self.stats.stubs += len(gone)


def _select(d: Detections, keep: NDArray[np.bool_]) -> Detections:
    """The detections where ``keep`` (k,) is true."""
    return Detections(
        classes=d.classes[keep],
        scores=d.scores[keep],
        points=d.points[keep],
        queries=None if d.queries is None else d.queries[keep],
        gt_ids=None if d.gt_ids is None else d.gt_ids[keep],
    )
