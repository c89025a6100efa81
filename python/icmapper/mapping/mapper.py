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
   that instance's id, so a lost track does not duplicate the map;
4. the global map is sampled in the patch expanded by ``fusion_margin`` (Rust ``sample_patch``);
5. fusion of every tracked detection with the history of its id;
6. merge into the global map (curve fit for polylines, union for crossings), or insert once the
   track has been seen in ``min_hits`` frames (tentative tracks keep one-off false positives out
   of the map; an extension like step 3).
"""

from __future__ import annotations

import hashlib
import os
import tempfile
import time
import zipfile
import zlib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from icmapper.data.types import (
    Frame,
    PerceptionRange,
    RANGE_60x30,
    Sequence,
    ego_to_world,
    pose_to_xy_yaw,
)
from icmapper.mapping.tracker import Track, Tracker, _segments, positional_affinity
from icmapper.mapping.types import Detections, DetectionSource, StepResult

if TYPE_CHECKING:
    import torch

    from icmapper._icmap import GlobalMap
    from icmapper.models.association import AssociationHead
    from icmapper.models.detector import MapDetector
    from icmapper.models.fusion import FusionModule

#: Share of a new track's points that must lie within ``reid_distance`` of a global instance for
#: the track to take that instance's id.
REID_MIN_OVERLAP = 0.5

#: The stages of one step, in order (timed in ``MapperStats.seconds``).
STAGES = ("detector", "association", "tracking", "sampling", "fusion", "merge")
#: Stages that run neural networks (the rest is tracking and geometry).
NETWORK_STAGES = ("detector", "association", "fusion")

#: Ids of detections that are reported (score >= detect_threshold) but not tracked start here, so
#: they never collide with track ids (the run format needs an id >= 0 for every prediction).
UNTRACKED_ID_BASE = 1 << 40

#: Format version of the ``Mapper.save_state`` sidecar (``<map>.state.npz``).
STATE_VERSION = 1
#: Integer counters of ``MapperStats`` stored in the sidecar, in order.
_STAT_COUNTS = ("frames", "inserted", "merged", "reidentified", "aliased", "merge_failures")
#: Arrays every sidecar holds (besides ``source.*``, the detection source's state).
_STATE_KEYS = (
    "version", "map_sha256", "source_kind", "next_id", "untracked", "stats_counts",
    "stats_seconds", "stats_failures", "alias", "track_ids", "track_cls", "track_age",
    "track_hits", "track_counts", "track_points", "track_has_query", "track_queries",
)  # fmt: skip


@dataclass(frozen=True)
class MapperConfig:
    """Inference settings of the online mapper (validated on construction)."""

    detect_threshold: float = 0.1  # detections reported per frame (evaluated by AP)
    track_threshold: float = 0.4  # detections associated, fused and merged into the map
    assoc_threshold: float = 0.5  # θ: minimum association score of a match
    max_age: int = 3  # frames a lost track stays in the buffer
    min_hits: int = 2  # frames a new track must be seen before it enters the global map
    positional_scale: float = 1.0  # metres; affinity exp(-chamfer/scale) without query features
    reid_distance: float = 1.0  # metres; 0 disables re-identification against the map
    fusion_margin: float = 20.0  # metres added around the perception range for the history
    history_points: int = 20
    smoothing: float = 0.5  # curve-fit s of the merge (scipy splprep semantics)
    spacing: float = 1.0  # metres between stored map points
    use_association: bool = True  # False: positional affinity even with query features
    use_fusion: bool = True  # False: detections are merged as detected

    def __post_init__(self) -> None:
        for name in ("detect_threshold", "track_threshold", "assoc_threshold"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"MapperConfig.{name} must be in [0, 1], got {v}")
        if self.track_threshold < self.detect_threshold:
            raise ValueError("MapperConfig.track_threshold must be >= detect_threshold")
        for name in ("positional_scale", "spacing", "history_points"):
            if not getattr(self, name) > 0:
                raise ValueError(f"MapperConfig.{name} must be > 0, got {getattr(self, name)}")
        if self.min_hits < 1:
            raise ValueError(f"MapperConfig.min_hits must be >= 1, got {self.min_hits}")
        for name in ("max_age", "reid_distance", "fusion_margin", "smoothing"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"MapperConfig.{name} must be >= 0, got {getattr(self, name)}")


class NetworkDetector:
    """The learned detector as a streaming ``DetectionSource`` (memory carried between frames).

    ``temporal=False`` gives the single-frame variant (no BEV memory, no query propagation).
    """

    def __init__(
        self, detector: MapDetector, device: str | torch.device = "cpu", temporal: bool = True
    ):
        import torch

        self.detector = detector.eval().to(device)
        self.device = torch.device(device)
        self.temporal = temporal
        self.reset()

    def reset(self) -> None:
        self._state: Any = None
        self._prev_pose: NDArray[np.float64] | None = None

    def state_dict(self) -> dict[str, NDArray[Any]]:
        """The streaming memory as numpy arrays (for ``Mapper.save_state``; no tensors, no pickle).

        Keys: ``has_state`` () bool; when true also ``bev`` (1, C, X, Y) float32, ``queries``
        (1, k, C) float32, ``points`` (1, k, P, 2) float32 in [0, 1], ``src_index`` (1, k) int64
        (the ``DetectorState``) and ``prev_pose`` (4, 4) float64 ego->world of the last frame.
        """
        if self._state is None or self._prev_pose is None:
            return {"has_state": np.array(False)}
        st = self._state
        return {
            "has_state": np.array(True),
            "bev": st.bev.detach().cpu().numpy(),  # (1, C, X, Y)
            "queries": st.queries.detach().cpu().numpy(),  # (1, k, C)
            "points": st.points.detach().cpu().numpy(),  # (1, k, P, 2)
            "src_index": st.src_index.detach().cpu().numpy(),  # (1, k)
            "prev_pose": np.asarray(self._prev_pose, np.float64).copy(),  # (4, 4)
        }

    def load_state_dict(self, state: dict[str, NDArray[Any]]) -> None:
        """Restores the memory written by ``state_dict`` (ValueError on missing keys, wrong
        shapes or dtypes; nothing changes then)."""
        import torch

        from icmapper.models.detector import DetectorState

        if "has_state" not in state or np.asarray(state["has_state"]).shape != ():
            raise ValueError("detector state: missing or malformed 'has_state'")
        if not bool(state["has_state"]):
            self.reset()
            return
        missing = {"bev", "queries", "points", "src_index", "prev_pose"} - set(state)
        if missing:
            raise ValueError(f"detector state: missing arrays {sorted(missing)}")
        spec = self.detector.spec
        bev, q, pts = state["bev"], state["queries"], state["points"]
        idx, pose = state["src_index"], state["prev_pose"]
        k = q.shape[1] if q.ndim == 3 else -1
        checks = [
            ("bev", bev, bev.ndim == 4 and bev.shape[:2] == (1, spec.channels), np.float32),
            ("queries", q, q.shape == (1, k, spec.channels), np.float32),
            ("points", pts, pts.shape == (1, k, spec.num_points, 2), np.float32),
            ("src_index", idx, idx.shape == (1, k), np.int64),
            ("prev_pose", pose, pose.shape == (4, 4), np.float64),
        ]
        for name, arr, ok, dtype in checks:
            if not ok or arr.dtype != dtype:
                raise ValueError(
                    f"detector state: {name} has shape {arr.shape} dtype {arr.dtype}, which does "
                    f"not fit the detector (channels {spec.channels}, points {spec.num_points})"
                )
            if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
                raise ValueError(f"detector state: {name} contains NaN or inf")
        if k > spec.num_queries or (idx.size and (idx.min() < 0 or idx.max() >= spec.num_queries)):
            raise ValueError("detector state: src_index out of range of the detector's queries")
        dev = self.device
        self._state = DetectorState(
            torch.from_numpy(bev.copy()).to(dev),  # (1, C, X, Y)
            torch.from_numpy(q.copy()).to(dev),  # (1, k, C)
            torch.from_numpy(pts.copy()).to(dev),  # (1, k, P, 2)
            torch.from_numpy(idx.copy()).to(dev),  # (1, k)
        )
        self._prev_pose = pose.astype(np.float64, copy=True)

    def detect(self, frame: Frame) -> Detections:
        import torch

        if frame.images is None:
            raise ValueError(f"frame {frame.index} has no images: the learned detector needs them")
        imgs = np.asarray(frame.images)
        rig = frame.rig
        if imgs.ndim != 4 or imgs.shape[0] != rig.num_cameras or imgs.shape[1] != 3:
            raise ValueError(
                f"frame {frame.index}: images must be ({rig.num_cameras}, 3, H, W), "
                f"got {imgs.shape}"
            )
        pose = np.asarray(frame.pose, dtype=np.float64)
        dev = self.device
        with torch.no_grad():
            images = torch.as_tensor(imgs, device=dev)[None]  # (1, C, 3, H, W)
            intr = torch.as_tensor(rig.intrinsics, dtype=torch.float32, device=dev)[None]
            c2e = torch.as_tensor(rig.cam_to_ego, dtype=torch.float32, device=dev)[None]
            state, motion = None, None
            if self.temporal and self._state is not None and self._prev_pose is not None:
                m = np.linalg.inv(pose) @ self._prev_pose  # (4, 4) previous ego -> current ego
                motion = torch.as_tensor(m, dtype=torch.float32, device=dev)[None]
                state = self._state
            out, new_state = self.detector(images, intr, c2e, state, motion)
            scores = out.scores()[0]  # (Q,)
            classes = out.classes()[0]  # (Q,)
            points = self.detector.to_metres(out.points[-1][0])  # (Q, P, 2) ego metres
            queries = out.queries[0]  # (Q, C)
        if self.temporal:
            self._state, self._prev_pose = new_state, pose
        order = torch.argsort(scores, descending=True)
        return Detections(
            classes=classes[order].cpu().numpy().astype(np.int64),
            scores=scores[order].cpu().numpy().astype(np.float32),
            points=points[order].cpu().numpy().astype(np.float32),
            queries=queries[order].cpu().numpy().astype(np.float32),
        )


@dataclass
class MapperStats:
    """Counters of one sequence (for logs and tests)."""

    frames: int = 0
    #: seconds spent per stage (STAGES)
    seconds: dict[str, float] = field(default_factory=lambda: dict.fromkeys(STAGES, 0.0))
    inserted: int = 0
    merged: int = 0
    reidentified: int = 0  # new tracks renamed to a global instance's id
    aliased: int = 0  # new tracks mapped into an instance already matched this frame
    merge_failures: int = 0
    failures: list[str] = field(default_factory=list)


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
        self._new_map()
        self.stats = MapperStats()
        self._untracked = UNTRACKED_ID_BASE
        self._alias: dict[int, int] = {}  # track id -> global instance id it maps into

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

        variant: "full" (IC-Mapper), "no-fusion" (detector + association), "base" (detector,
        positional association, no fusion: StreamMapNet-like + post tracking), "single-frame"
        (like "base" without temporal memory: MapTR-like).
        """
        from icmapper.training.checkpoint import load_checkpoint
        from icmapper.training.config import config_from_dict
        from icmapper.training.objectives import ICMapperNet

        blob = load_checkpoint(path, map_location=device)
        tcfg = config_from_dict(blob["config"])
        net = ICMapperNet(tcfg)
        try:
            net.load_state_dict(blob["model"])
        except RuntimeError as exc:
            raise ValueError(f"checkpoint {path} does not fit its config: {exc}") from None
        variants = {
            "full": (True, True, True),
            "no-fusion": (True, True, False),
            "base": (True, False, False),
            "single-frame": (False, False, False),
        }
        if variant not in variants:
            raise ValueError(f"unknown variant {variant!r}; expected one of {sorted(variants)}")
        temporal, use_assoc, use_fusion = variants[variant]
        cfg = config or MapperConfig(detect_threshold=tcfg.score_threshold)
        cfg = replace(cfg, use_association=use_assoc, use_fusion=use_fusion)
        name = "icmapper" if variant == "full" else f"icmapper-{variant}"
        return cls(
            NetworkDetector(net.detector, device, temporal=temporal),
            association=net.association.to(device),
            fusion=net.fusion.to(device),
            config=cfg,
            rng=tcfg.perception_range,
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

    @property
    def global_map(self) -> GlobalMap:
        return self._map

    def reset(self) -> None:
        """A new sequence: empty map, empty buffer, detector memory cleared."""
        self.source.reset()
        self.tracker.reset()
        self._new_map()
        self.stats = MapperStats()
        self._untracked = UNTRACKED_ID_BASE
        self._alias: dict[int, int] = {}  # track id -> global instance id it maps into

    def save_state(self, path: str | Path) -> None:
        """Saves everything the next step depends on, so that ``resume(path)`` on a mapper built
        the same way continues exactly like this one.

        Writes ``path`` (the native global map file) and the sidecar ``<path>.state.npz`` (plain
        numpy arrays, no pickle, format ``STATE_VERSION``): the tracking buffer (ids, classes,
        world points, queries, ages, hits), the next track id, the track aliases, the untracked
        id counter, the stats, the SHA-256 of the map file (ties the pair together) and the
        detection source's memory when it has one (``state_dict()``, e.g. ``NetworkDetector``).
        Both files are written atomically.
        """
        path = Path(path)
        sidecar = state_path(path)
        arrays = self._state_arrays()
        self._map.save(path)
        arrays["map_sha256"] = np.array(_sha256(path))
        fd, tmp = tempfile.mkstemp(prefix=sidecar.name + ".", suffix=".tmp", dir=sidecar.parent)
        try:
            with os.fdopen(fd, "wb") as fh:
                np.savez(fh, **arrays)
            os.replace(tmp, sidecar)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise

    def _state_arrays(self) -> dict[str, NDArray[Any]]:
        """The sidecar's arrays (all but ``map_sha256``); see ``save_state``."""
        tracks = self.tracker._tracks
        counts = np.array([len(t.points) for t in tracks], np.int64)  # (t,)
        pts = [np.asarray(t.points, np.float64).reshape(-1, 2) for t in tracks]
        has_q = np.array([t.query is not None for t in tracks], bool)  # (t,)
        dims = {int(np.asarray(t.query).shape[0]) for t in tracks if t.query is not None}
        if len(dims) > 1:
            raise ValueError(f"save_state: tracks have queries of different sizes {sorted(dims)}")
        dim = dims.pop() if dims else 0
        queries = np.zeros((len(tracks), dim), np.float32)  # (t, D)
        for i, t in enumerate(tracks):
            if t.query is not None:
                queries[i] = t.query
        st = self.stats
        arrays: dict[str, NDArray[Any]] = {
            "version": np.array(STATE_VERSION, np.int64),
            "source_kind": np.array(type(self.source).__name__),
            "next_id": np.array(self.tracker._next_id, np.int64),
            "untracked": np.array(self._untracked, np.int64),
            "stats_counts": np.array([getattr(st, n) for n in _STAT_COUNTS], np.int64),
            "stats_seconds": np.array([st.seconds.get(n, 0.0) for n in STAGES], np.float64),
            "stats_failures": np.array(st.failures, dtype=str).reshape(-1),
            "alias": np.array(sorted(self._alias.items()), np.int64).reshape(-1, 2),  # (a, 2)
            "track_ids": np.array([t.id for t in tracks], np.int64),  # (t,)
            "track_cls": np.array([t.cls for t in tracks], np.int64),
            "track_age": np.array([t.age for t in tracks], np.int64),
            "track_hits": np.array([t.hits for t in tracks], np.int64),
            "track_counts": counts,
            "track_points": np.concatenate(pts) if pts else np.zeros((0, 2)),  # (sum n, 2)
            "track_has_query": has_q,
            "track_queries": queries,
        }
        if hasattr(self.source, "state_dict"):
            for key, val in self.source.state_dict().items():
                arrays["source." + key] = np.asarray(val)
        return arrays

    def resume(self, path: str | Path) -> None:
        """Continues a saved run.

        With the sidecar ``<path>.state.npz`` of ``save_state``: restores the map, the tracking
        buffer, the aliases, the counters, the stats and the detector memory, so the continuation
        is identical to the uninterrupted run (the mapper must be built with the same source,
        networks and config). Without a sidecar (a map saved with ``global_map.save``): loads the
        map only, clears the buffer and the detector memory and starts new ids above the map's
        largest id. A bad map file or sidecar raises ValueError naming the file; nothing changes.
        """
        from icmapper._icmap import GlobalMap

        path = Path(path)
        sidecar = state_path(path)
        if not sidecar.exists():
            gmap = GlobalMap.load(str(path))
            self.source.reset()
            self.tracker.reset()
            self._alias = {}
            self._map = gmap
            ids = gmap.ids()
            self.tracker.reserve_ids(int(ids.max()) + 1 if len(ids) else 0)
            return
        state = _read_state(sidecar)
        try:
            tracks, restore = self._parse_state(state, path)
        except (ValueError, KeyError, TypeError, IndexError) as exc:
            raise ValueError(f"mapper state {sidecar}: {exc}") from None
        gmap = GlobalMap.load(str(path))
        src_state = {k[7:]: v for k, v in state.items() if k.startswith("source.")}
        if hasattr(self.source, "load_state_dict"):
            old = self.source.state_dict() if hasattr(self.source, "state_dict") else None
            try:
                self.source.load_state_dict(src_state)
            except (ValueError, KeyError, TypeError) as exc:
                if old is not None:
                    self.source.load_state_dict(old)
                raise ValueError(f"mapper state {sidecar}: {exc}") from None
        else:
            self.source.reset()
        self._map = gmap
        self.tracker.reset()
        self.tracker._tracks = tracks
        self.tracker._next_id = restore["next_id"]
        self._alias = restore["alias"]
        self._untracked = restore["untracked"]
        self.stats = restore["stats"]

    def _parse_state(
        self, z: dict[str, NDArray[Any]], map_path: Path
    ) -> tuple[list[Track], dict[str, Any]]:
        """Validates the sidecar arrays and builds the tracker buffer and counters from them."""
        version = int(z["version"])
        if version != STATE_VERSION:
            raise ValueError(f"format version {version}, this build reads {STATE_VERSION}")
        if str(z["map_sha256"]) != _sha256(map_path):
            raise ValueError(f"it was not saved with the map file {map_path} (checksum differs)")
        kind = str(z["source_kind"])
        if kind != type(self.source).__name__:
            raise ValueError(
                f"saved with a {kind} source, this mapper has a {type(self.source).__name__}"
            )
        has_src = any(k.startswith("source.") for k in z)
        if has_src != hasattr(self.source, "load_state_dict"):
            raise ValueError("the detection source state does not fit this mapper's source")
        ids, cls = _int_array(z, "track_ids"), _int_array(z, "track_cls")
        age, hits = _int_array(z, "track_age"), _int_array(z, "track_hits")
        counts = _int_array(z, "track_counts")
        t = len(ids)
        has_q = z["track_has_query"]
        queries, pts = z["track_queries"], z["track_points"]
        for name, arr in (("track_cls", cls), ("track_age", age), ("track_hits", hits),
                          ("track_counts", counts), ("track_has_query", has_q)):  # fmt: skip
            if arr.shape != (t,):
                raise ValueError(f"{name} has shape {arr.shape}, expected ({t},)")
        if has_q.dtype != bool or queries.ndim != 2 or queries.shape[0] != t:
            raise ValueError(f"track_queries {queries.shape} / has_query do not fit {t} tracks")
        if queries.dtype != np.float32 or not np.all(np.isfinite(queries)):
            raise ValueError("track_queries must be finite float32")
        if pts.dtype != np.float64 or pts.ndim != 2 or pts.shape[1] != 2:
            raise ValueError(f"track_points must be (n, 2) float64, got {pts.shape} {pts.dtype}")
        if not np.all(np.isfinite(pts)):
            raise ValueError("track_points contain NaN or inf")
        if np.any(counts < 1) or int(counts.sum()) != len(pts):
            raise ValueError(f"track_counts (sum {int(counts.sum())}) do not fit {len(pts)} points")
        if len(set(ids.tolist())) != t or np.any(age < 0) or np.any(hits < 1):
            raise ValueError("duplicate track ids, negative ages or hits < 1")
        offsets = np.concatenate([[0], np.cumsum(counts)])
        tracks = [
            Track(
                int(ids[i]),
                int(cls[i]),
                pts[offsets[i] : offsets[i + 1]].copy(),  # (n, 2) world
                queries[i].copy() if has_q[i] else None,  # (D,)
                int(age[i]),
                int(hits[i]),
            )
            for i in range(t)
        ]
        alias = _int_array(z, "alias", ndim=2)
        if alias.shape[1:] != (2,):
            raise ValueError(f"alias must be (a, 2), got {alias.shape}")
        counts_s = _int_array(z, "stats_counts")
        seconds = z["stats_seconds"]
        if counts_s.shape != (len(_STAT_COUNTS),) or seconds.shape != (len(STAGES),):
            raise ValueError(f"stats arrays have shapes {counts_s.shape}, {seconds.shape}")
        failures = z["stats_failures"]
        if failures.ndim != 1 or failures.dtype.kind != "U":
            raise ValueError("stats_failures must be a 1-d string array")
        stats = MapperStats(
            seconds={n: float(v) for n, v in zip(STAGES, seconds, strict=True)},
            failures=[str(f) for f in failures],
            **{n: int(v) for n, v in zip(_STAT_COUNTS, counts_s, strict=True)},
        )
        restore = {
            "next_id": int(_int_array(z, "next_id", ndim=0)),
            "untracked": int(_int_array(z, "untracked", ndim=0)),
            "alias": {int(a): int(b) for a, b in alias},
            "stats": stats,
        }
        return tracks, restore

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
        fused = self._fuse(det, track_ids, hist_row, hist_pts)  # (m, P, 2) ego
        t4 = time.perf_counter()
        sec["fusion"] += t4 - t3

        inserted, merged = self._merge(det, track_ids, fused, pose, frame.index)
        sec["merge"] += time.perf_counter() - t4

        all_ids = np.empty(len(dets), np.int64)
        all_ids[tracked] = track_ids
        n_untracked = int((~tracked).sum())
        all_ids[~tracked] = np.arange(self._untracked, self._untracked + n_untracked)
        self._untracked += n_untracked
        points = dets.points.copy()
        points[tracked] = fused
        self.stats.frames += 1
        return StepResult(frame.index, dets, all_ids, points, inserted, merged)

    def _associate(self, det: Detections, pose: NDArray[np.float64]) -> NDArray[np.int64]:
        t0 = time.perf_counter()
        trk_ids, trk_cls, trk_pts, trk_q = self.tracker.tracks_in_ego(pose)
        k, t = len(det), len(trk_ids)
        if k == 0 or t == 0:
            scores = np.zeros((k, t), np.float64)
        elif (
            self.config.use_association
            and self.association is not None
            and det.queries is not None
            and trk_q is not None
        ):
            import torch

            unit = self.source.detector.to_unit  # type: ignore[attr-defined]
            dev = self.device
            with torch.no_grad():
                s = self.association.scores(
                    torch.as_tensor(det.queries, device=dev),
                    unit(torch.as_tensor(det.points, device=dev)),
                    torch.as_tensor(trk_q, device=dev),
                    unit(torch.as_tensor(trk_pts, device=dev)),
                )  # (k, t)
            scores = s.cpu().numpy().astype(np.float64)
        else:
            scores = positional_affinity(
                det.points,
                det.classes,
                trk_pts,
                trk_cls,
                scale=self.config.positional_scale,
                reduce="min",  # instances grow and shrink at the range edge
            )
        t1 = time.perf_counter()
        ids = self.tracker.assign(scores, det.classes, det.points, pose, det.queries)
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
        """New tracks lying on a same-class global instance take its id (see module docstring).
        hist_row: global id -> row of the sampled history (hist_cls (k,), hist_pts (k, S, 2))."""
        limit = self.config.reid_distance
        if limit <= 0 or not hist_row:
            return track_ids
        ids = track_ids.copy()
        taken = {int(i) for i in ids if int(i) in hist_row}
        for j, tid in enumerate(ids.tolist()):
            if tid in self._map or tid in hist_row or tid in self._alias:
                continue  # an existing instance: nothing to re-identify
            cls = int(det.classes[j])
            cands = [(gid, row) for gid, row in hist_row.items() if int(hist_cls[row]) == cls]
            if not cands:
                continue
            hist = hist_pts[[r for _, r in cands]].astype(np.float64)  # (c, S, 2)
            segs = _segments(hist, np.full(len(cands), cls == 0))  # (c, S, 2, 2)
            dist = _point_to_segments(det.points[j].astype(np.float64), segs)  # (c, P)
            # share of the detection lying on the instance: a piece that slid along the
            # instance or grew at the range edge still overlaps it over most of its length
            overlap = (dist <= limit).mean(axis=1)  # (c,)
            best = int(np.argmax(overlap - 1e-3 * dist.mean(axis=1)))
            d = np.where(overlap >= REID_MIN_OVERLAP, 0.0, np.inf)  # (c,)
            if d[best] <= limit:
                gid = cands[best][0]
                if gid in taken:
                    # another piece of the same instance (clipped into several pieces): the
                    # track keeps its id and maps into the instance
                    self._alias[tid] = gid
                    self.stats.aliased += 1
                else:
                    self.tracker.rename(tid, gid)
                    ids[j] = gid
                    taken.add(gid)
                    self.stats.reidentified += 1
        return ids

    def _fuse(
        self,
        det: Detections,
        track_ids: NDArray[np.int64],
        hist_row: dict[int, int],
        hist_pts: NDArray[np.float32],
    ) -> NDArray[np.float32]:
        if not (self.config.use_fusion and self.fusion is not None) or len(det) == 0:
            return det.points.copy()
        targets = [self._alias.get(int(i), int(i)) for i in track_ids]
        has = np.array([t in hist_row for t in targets], bool)  # (m,)
        if not has.any():
            return det.points.copy()
        import torch

        s = self.config.history_points
        hist = np.zeros((len(det), s, 2), np.float32)  # (m, S, 2)
        hist[has] = hist_pts[[hist_row[t] for t, h in zip(targets, has, strict=True) if h]]
        dev = self.device
        with torch.no_grad():
            out = self.fusion(
                torch.as_tensor(det.points, device=dev),
                torch.as_tensor(det.classes, device=dev),
                torch.as_tensor(hist, device=dev),
                torch.as_tensor(has, device=dev),
            )[-1]  # (m, P, 2) metres
        return out.cpu().numpy().astype(np.float32)

    def _note_failure(self, frame_index: int, target: int, exc: BaseException) -> None:
        """Counts a rejected insert or merge (degenerate geometry) and keeps the first 20."""
        self.stats.merge_failures += 1
        if len(self.stats.failures) < 20:
            self.stats.failures.append(f"frame {frame_index}, id {target}: {exc}")

    def _merge(
        self,
        det: Detections,
        track_ids: NDArray[np.int64],
        fused: NDArray[np.float32],
        pose: NDArray[np.float64],
        frame_index: int,
    ) -> tuple[list[int], list[int]]:
        inserted: list[int] = []
        merged: list[int] = []
        # Inserts now (a later detection of this frame may merge into a new instance), merges
        # collected and run in one parallel merge_many call: the same map as merging in order.
        merge_items: list[tuple[int, int, NDArray[np.float64]]] = []  # (track, target, world)
        for j, tid in enumerate(track_ids.tolist()):
            world = ego_to_world(fused[j], pose)  # (P, 2)
            target = self._alias.get(tid, tid)  # the global instance this track maps into
            if target in self._map:
                merge_items.append((tid, target, world))
                continue
            if self.tracker.track(tid).hits < self.config.min_hits:
                continue  # tentative track: not in the map until confirmed
            try:
                self._map.insert_with_id(tid, int(det.classes[j]), world, frame=frame_index)
            except ValueError as exc:  # degenerate geometry (e.g. a collapsed detection)
                self._note_failure(frame_index, target, exc)
                continue
            inserted.append(tid)
            self.tracker.set_points(tid, world)
        if merge_items:
            errors = self._map.merge_many(
                [t for _, t, _ in merge_items], [w for _, _, w in merge_items], frame=frame_index
            )
            for (tid, target, world), exc in zip(merge_items, errors, strict=True):
                if exc is not None:
                    self._note_failure(frame_index, target, exc)
                    continue
                merged.append(target)
                self.tracker.set_points(tid, world)
        self.stats.inserted += len(inserted)
        self.stats.merged += len(merged)
        return inserted, merged


def _point_to_segments(p: NDArray[np.float64], seg: NDArray[np.float64]) -> NDArray[np.float64]:
    """p (n, 2), seg (c, S, 2, 2) -> (c, n): distance of every point to the nearest segment."""
    a, b = seg[:, None, :, 0], seg[:, None, :, 1]  # (c, 1, S, 2)
    ab = b - a  # (c, 1, S, 2)
    ap = p[None, :, None, :] - a  # (c, n, S, 2)
    t = np.clip((ap * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-18), 0.0, 1.0)  # (c, n, S)
    off = ap - t[..., None] * ab  # (c, n, S, 2)
    return np.sqrt((off * off).sum(-1)).min(axis=2)  # (c, n)


def _select(d: Detections, keep: NDArray[np.bool_]) -> Detections:
    return Detections(
        classes=d.classes[keep],
        scores=d.scores[keep],
        points=d.points[keep],
        queries=None if d.queries is None else d.queries[keep],
        gt_ids=None if d.gt_ids is None else d.gt_ids[keep],
    )


def state_path(map_path: str | Path) -> Path:
    """The sidecar of a saved map: ``<map_path>.state.npz`` (see ``Mapper.save_state``)."""
    p = Path(map_path)
    return p.with_name(p.name + ".state.npz")


def _sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _read_state(sidecar: Path) -> dict[str, NDArray[Any]]:
    """All arrays of a sidecar (ValueError naming the file if it is not a readable npz)."""
    try:
        with np.load(sidecar, allow_pickle=False) as z:
            out = {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error, KeyError) as exc:
        raise ValueError(f"mapper state {sidecar} is not a valid state file: {exc}") from None
    missing = set(_STATE_KEYS) - set(out)
    if missing:
        raise ValueError(f"mapper state {sidecar}: missing arrays {sorted(missing)}")
    return out


def _int_array(z: dict[str, NDArray[Any]], key: str, ndim: int = 1) -> NDArray[np.int64]:
    arr = z[key]
    if arr.dtype != np.int64 or arr.ndim != ndim:
        raise ValueError(f"{key} must be a {ndim}-d int64 array, got {arr.shape} {arr.dtype}")
    return arr
