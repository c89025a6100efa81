"""Change detection against a stored city map: what changed on the road since the map was built.

``ChangeDetector`` compares, frame by frame, what is detected with the stored map inside the
perception range (detections taken to the world frame with the frame's pose) and gathers
evidence; ``decide`` turns the evidence into confirmed ``Change``s and ``apply_changes`` applies
them to a ``GlobalMap``. Pure logic: no I/O, no detector, no files (``city.update_run`` is the
glue of ``icmapper map --city-mode update``).

Per frame and class, with the stored instances of the range and the detections (score >=
``score_threshold``, densified to 0.5 m):

- every stored point inside the range shrunk by ``margin`` is *expected*; it is *seen* when a
  detection point of its class lies within ``gate`` metres; its signed sideways offset to that
  nearest detection point (along the stored line's left normal) is recorded;
- an instance with >= ``min_points`` expected points is *seen* in the frame when at least
  ``seen_share`` of them are seen, else *missed*;
- every stored point near the range claims the detection of its nearest detection point; a
  detection point is *explained* when its nearest stored point (within ``gate``) claimed that
  detection. The longest run of unexplained points of a detection (>= ``min_add_length`` m, a
  crossing: the ring when most of it is unexplained), where the stored map covers the ground
  (``coverage``: the city's drives saw it), is a sighting of a candidate addition; sightings
  within ``add_gate`` of each other are one candidate.

Decisions (``decide``), from all frames of all drives observed:

- removed: an instance expected in >= ``remove_frames`` frames and missed in at least
  ``remove_share`` of them; or, with a ``reference`` (below) and for the classes with a finite
  ``remove_drop``, one that did not move and was missed at ``remove_gate`` (a tighter gate) in a
  share of its frames at least ``remove_drop`` above the reference's share, a rise the frames
  counted make significant (a one-sided two-proportion z-test at ``remove_z``: 4 misses in 8
  frames against the reference's 2 in 8 are not evidence enough);
- moved (polylines): stored points with >= ``move_obs`` offsets whose median is beyond
  ``move_threshold`` (the noise; per class), in a run of >= ``move_length`` m (per class); when
  the run holds most of the observed points the whole line moves by the run's median, else the
  run moves by its smoothed medians, with ramps down to a quarter of its peak (<= ``RAMP`` m);
- added: a candidate sighted in >= ``add_frames`` frames and in at least ``add_share`` of the
  frames in which it was in view; its geometry is the engine's merge of its sightings (a crossing:
  the sighting closest to all others).

With a ``reference`` (``decide(reference=...)``: the same detector fed with the city's own drives,
the detections the map was built from), what the detector already showed before the change is
taken out: a stored point's offset counts relative to the reference's median offset there
(the detector's own bias at that place: a learned detector draws some lines a fixed 0.3-0.6 m
off the map, and a move is what changed beyond that).

A frame of a drive whose car still stands where it stood at that drive's last frame observed
(within ``min_travel``, ``data.types.stands_still``) gathers no evidence: a car stopped at a light
shows one view, and counting it once per frame would confirm a removal from a line hidden behind
one lorry.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from icmapper.data.gt import in_range_counts
from icmapper.data.types import (
    CLASS_NAMES,
    MapClass,
    PerceptionRange,
    pose_to_xy_yaw,
    stands_still,
)

if TYPE_CHECKING:
    from icmapper._icmap import GlobalMap

#: Longest ramp (m) of a moved section beyond its points that moved further than the threshold.
RAMP = 8.0
#: A frame of an update run: (drive id, frame index in the drive).
FrameKey = tuple[int, int]


@dataclass(frozen=True)
class UpdateConfig:
    """Thresholds of the change detector (see the module docstring; metres, shares in [0, 1])."""

    score_threshold: float = 0.5
    margin: float = 1.0
    gate: tuple[float, float, float] = (2.5, 2.5, 3.5)  # per class: crossing, divider, boundary
    min_points: int = 3
    seen_share: float = 0.3
    remove_frames: int = 3
    remove_share: float = 0.8
    remove_drop: tuple[float, float, float] = (np.inf, 0.25, np.inf)  # per class
    remove_gate: float = 1.0
    remove_z: float = 1.645  # one-sided 5 % (twenty-fourth round; 0: no test)
    move_threshold: tuple[float, float, float] = (np.inf, 0.4, 1.0)  # per class
    move_obs: int = 3
    move_length: tuple[float, float, float] = (np.inf, 12.0, 8.0)  # per class (lane lines: 4 m
    # until the fifteenth round, 6 m until the twenty-fourth; docs/mapping.md)
    min_add_length: float = 3.0
    add_gate: float = 1.0
    add_frames: int = 3
    add_share: float = 0.5
    min_travel: float = 0.5  # metres: a frame of a car standing still is evidence once

    def __post_init__(self) -> None:
        if len(self.remove_drop) != 3 or not all(x > 0 for x in self.remove_drop):
            raise ValueError(
                f"UpdateConfig.remove_drop must be 3 values > 0, got {self.remove_drop}"
            )
        for name in (
            "margin",
            "min_add_length",
            "add_gate",
            "remove_gate",
            "remove_z",
            "min_travel",
        ):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"UpdateConfig.{name} must be finite and >= 0, got {v}")
        for name in ("move_threshold", "move_length"):
            v = getattr(self, name)
            if len(v) != 3 or not all(x > 0 for x in v):
                raise ValueError(f"UpdateConfig.{name} must be 3 positive values, got {v}")
        for name in ("score_threshold", "seen_share", "remove_share", "add_share"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"UpdateConfig.{name} must be in [0, 1], got {v}")
        if len(self.gate) != 3 or not all(np.isfinite(g) and g > 0 for g in self.gate):
            raise ValueError(f"UpdateConfig.gate must be 3 positive distances, got {self.gate}")


@dataclass
class Evidence:
    """Frames in which a stored instance or a candidate should have been seen, was seen, was
    missed (each a list of (drive, frame))."""

    expected: list[FrameKey] = field(default_factory=list)
    seen: list[FrameKey] = field(default_factory=list)
    missed: list[FrameKey] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        return {
            "expected": len(self.expected),
            "seen": len(self.seen),
            "missed": len(self.missed),
            "frames": {
                "expected": [list(k) for k in self.expected],
                "seen": [list(k) for k in self.seen],
                "missed": [list(k) for k in self.missed],
            },
        }

    def drives(self) -> list[int]:
        return sorted({d for d, _ in self.expected + self.seen})

    def mostly_missed(self, frames: int, share: float) -> bool:
        """Whether it was expected in at least ``frames`` frames and missed in at least
        ``frames`` of them and at least ``share`` of them (a city update's removal test, and
        ``mapping.verify``'s)."""
        n, k = len(self.expected), len(self.missed)
        return n >= frames and k >= frames and k >= share * n


@dataclass
class Change:
    """A confirmed change: ``change`` (added | removed | moved), class, the map ``instance`` id
    (an addition's once applied; -1 before), ``points`` (n, 2) world frame: the geometry after
    the change (a removal's: the stored one; a move's: the moved part), ``before``: a move's
    stored part (None else), the instance's full geometry after the change (``new_points``:
    what the map stores; None for a removal), ``closed``, the evidence, ``offset`` (a move's
    median sideways offset, metres) and ``cause``: "road" (the road changed), or "map" when the
    city's own drives already disagreed with the map there (``mark_map_errors``): the map was
    wrong before, the road did not change."""

    change: str
    cls: int
    instance: int
    points: NDArray[np.float64]
    closed: bool
    evidence: Evidence
    before: NDArray[np.float64] | None = None
    new_points: NDArray[np.float64] | None = None
    offset: float = 0.0
    cause: str = "road"

    @property
    def class_name(self) -> str:
        return CLASS_NAMES[self.cls]


def _left_normals(points: NDArray[np.float64]) -> NDArray[np.float64]:
    d = np.gradient(points, axis=0)  # (n, 2)
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
    return np.stack([-d[:, 1], d[:, 0]], axis=1)  # (n, 2)


def _dense(points: NDArray[np.float64], closed: bool, spacing: float = 0.5) -> NDArray[np.float64]:
    from icmapper import geom

    pts = np.asarray(points, np.float64)
    if len(pts) < (3 if closed else 2):
        return pts
    try:
        return geom.resample_spacing(pts, spacing, closed=closed)  # (m, 2)
    except ValueError:  # zero length
        return pts


def _runs(mask: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """[start, stop) of the runs of True in a 1-D mask."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(np.int8), [0]])))
    return list(zip(edges[0::2].tolist(), edges[1::2].tolist(), strict=True))


@dataclass
class Stored:
    """A stored instance and its evidence."""

    cls: int
    points: NDArray[np.float64]  # (n, 2)
    normals: NDArray[np.float64]  # (n, 2)
    closed: bool
    evidence: Evidence = field(default_factory=Evidence)
    obs_idx: list[NDArray[np.int64]] = field(default_factory=list)  # per frame: point indices
    obs_off: list[NDArray[np.float64]] = field(default_factory=list)  # per frame: offsets
    obs_keys: list[FrameKey] = field(default_factory=list)
    near_missed: int = 0  # expected frames without a detection within remove_gate
    point_expected: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    point_near: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    # per point (n,): frames in which it was expected, and in which a detection of its class
    # lay within remove_gate of it (mapping.verify trims a line's unbacked ends by them)

    def __post_init__(self) -> None:
        if len(self.point_expected) != len(self.points):
            self.point_expected = np.zeros(len(self.points), np.int64)
            self.point_near = np.zeros(len(self.points), np.int64)

    def near_missed_share(self) -> float:
        return self.near_missed / max(len(self.evidence.expected), 1)


@dataclass
class _Candidate:
    """A candidate addition: its sightings (world points) and evidence."""

    cls: int
    sightings: list[NDArray[np.float64]] = field(default_factory=list)
    evidence: Evidence = field(default_factory=Evidence)
    cloud: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 2)))

    def add(self, key: FrameKey, pts: NDArray[np.float64]) -> None:
        self.sightings.append(pts)
        if not self.evidence.seen or self.evidence.seen[-1] != key:
            self.evidence.seen.append(key)
        self.cloud = np.concatenate([self.cloud, pts])


class ChangeDetector:
    """Gathers change evidence of drives against a stored map (module docstring).

    gmap: the stored city map (read only here); rng: the perception range; covered: a function
    (m, 2) world points -> (m,) bool, whether the stored map covers them (its drives saw them;
    additions are only looked for there), None to look for no additions (only the stored
    instances' evidence: ``mapping.verify``); config: the thresholds."""

    def __init__(
        self,
        gmap: GlobalMap,
        rng: PerceptionRange,
        covered: Callable[[NDArray[np.float64]], NDArray[np.bool_]] | None,
        config: UpdateConfig = UpdateConfig(),
    ) -> None:
        self.gmap, self.rng, self.covered, self.cfg = gmap, rng, covered, config
        self.stored: dict[int, Stored] = {}
        self.candidates: list[_Candidate] = []
        self.frames: list[FrameKey] = []
        self.still = 0  # frames left out: the car stood still (``min_travel``)
        self._last: dict[int, tuple[float, float, float]] = {}  # drive -> last pose observed

    def _stored(self, i: int) -> Stored:
        if i not in self.stored:
            cls, pts = self.gmap.get(i)
            closed = bool(self.gmap.info(i)["closed"])
            pts = np.asarray(pts, np.float64)
            self.stored[i] = Stored(int(cls), pts, _left_normals(pts), closed)
        return self.stored[i]

    def observe(
        self,
        key: FrameKey,
        pose: NDArray[np.float64],
        classes: NDArray[np.int64],
        scores: NDArray[np.floating],
        points: NDArray[np.floating],
    ) -> None:
        """One frame: ``pose`` (4, 4) ego -> world, detections ``classes`` (k,), ``scores``
        (k,), ``points`` (k, n, 2) in the ego frame. A frame of a drive whose car still stands
        where it stood at that drive's last frame observed (``data.types.stands_still`` with
        ``min_travel``) is left out: a stopped car's view is one piece of evidence, not one per
        frame (a line hidden behind a lorry at a light is not missed 30 times)."""
        from icmapper.data.types import ego_to_world

        xyyaw = pose_to_xy_yaw(pose)
        if stands_still(xyyaw, self._last.get(key[0]), self.cfg.min_travel):
            self.still += 1
            return
        self._last[key[0]] = xyyaw
        self.frames.append(key)
        keep = np.asarray(scores) >= self.cfg.score_threshold  # (k,)
        world = [ego_to_world(p, pose) for p in np.asarray(points)[keep]]  # k' x (n, 2)
        cls_of = np.asarray(classes)[keep]  # (k',)
        ids = self.gmap.query(xyyaw, (self.rng.half_x, self.rng.half_y), self.cfg.gate[2])
        stored = [(int(i), self._stored(int(i))) for i in ids.tolist()]
        for c in range(len(CLASS_NAMES)):
            closed = c == MapClass.PED_CROSSING
            dets = [_dense(w, closed) for w, k in zip(world, cls_of, strict=True) if k == c]
            self._observe_class(key, pose, c, dets, [(i, s) for i, s in stored if s.cls == c])
        self._candidates_in_view(key, pose)

    def _observe_class(
        self,
        key: FrameKey,
        pose: NDArray[np.float64],
        c: int,
        dets: list[NDArray[np.float64]],
        stored: list[tuple[int, Stored]],
    ) -> None:
        cfg, gate = self.cfg, self.cfg.gate[c]
        q = np.concatenate(dets) if dets else np.zeros((0, 2))  # (Q, 2) detection points
        lab = np.repeat(np.arange(len(dets)), [len(d) for d in dets])  # (Q,)
        tree = cKDTree(q) if len(q) else None
        claim_pts, claim_lab = [], []  # stored points near the range and the detection they claim
        additions = self.covered is not None
        for _, s in stored:
            expected = in_range_counts(s.points, pose[None], self.rng, cfg.margin) > 0  # (n,)
            near = (
                in_range_counts(s.points, pose[None], self.rng, margin=-gate) > 0
                if additions and tree is not None
                else np.zeros(len(s.points), bool)
            )  # (n,)
            if tree is not None and near.any():
                dist, j = tree.query(s.points[near], distance_upper_bound=gate)  # (m,), (m,)
                hit = np.isfinite(dist)
                claim_pts.append(s.points[near][hit])
                claim_lab.append(lab[j[hit]])
            if expected.sum() < cfg.min_points:
                continue
            s.evidence.expected.append(key)
            idx = np.flatnonzero(expected)  # (e,)
            s.point_expected[idx] += 1
            if tree is None:
                s.evidence.missed.append(key)
                s.near_missed += 1
                continue
            dist, j = tree.query(s.points[idx], distance_upper_bound=gate)  # (e,), (e,)
            hit = np.isfinite(dist)  # (e,)
            s.point_near[idx[dist <= cfg.remove_gate]] += 1
            if np.mean(dist <= cfg.remove_gate) < cfg.seen_share:
                s.near_missed += 1
            if hit.mean() >= cfg.seen_share:
                s.evidence.seen.append(key)
            else:
                s.evidence.missed.append(key)
            if not s.closed and hit.any():
                delta = q[j[hit]] - s.points[idx[hit]]  # (h, 2)
                s.obs_idx.append(idx[hit])
                s.obs_off.append(np.einsum("hk,hk->h", delta, s.normals[idx[hit]]))  # (h,)
                s.obs_keys.append(key)
        if not dets or not additions:
            return
        owner = cKDTree(np.concatenate(claim_pts)) if claim_pts else None
        owner_lab = np.concatenate(claim_lab) if claim_lab else np.zeros(0, np.int64)
        for d, pts in enumerate(dets):
            explained = np.zeros(len(pts), bool)  # (m,)
            if owner is not None and len(owner_lab):
                dist, j = owner.query(pts, distance_upper_bound=gate)  # (m,), (m,)
                ok = np.isfinite(dist)
                explained[ok] = owner_lab[j[ok]] == d
            self._sighting(key, c, pts, explained)

    def _sighting(
        self, key: FrameKey, c: int, pts: NDArray[np.float64], explained: NDArray[np.bool_]
    ) -> None:
        """The unexplained part of a detection (m, 2) as a sighting of a candidate addition."""
        if self.covered is None:  # no additions looked for
            return
        free = ~explained & self.covered(pts)  # (m,)
        if c == MapClass.PED_CROSSING:
            if free.mean() < 0.5:
                return
            piece = pts
        else:
            runs = _runs(free)
            if not runs:
                return
            a, b = max(runs, key=lambda r: r[1] - r[0])
            piece = pts[a:b]
            if len(piece) < 2 or np.linalg.norm(np.diff(piece, axis=0), axis=1).sum() < (
                self.cfg.min_add_length
            ):
                return
        best, share = None, 0.0
        for cand in self.candidates:
            if cand.cls != c:
                continue
            d, _ = cKDTree(cand.cloud).query(piece)  # (m,)
            s = float(np.mean(d <= self.cfg.add_gate))
            if s > share:
                best, share = cand, s
        if best is None or share < 0.5:
            best = _Candidate(c)
            self.candidates.append(best)
        best.add(key, piece)

    def _candidates_in_view(self, key: FrameKey, pose: NDArray[np.float64]) -> None:
        for cand in self.candidates:
            inside = in_range_counts(cand.cloud, pose[None], self.rng, self.cfg.margin) > 0
            if inside.sum() >= self.cfg.min_points or cand.evidence.seen[-1] == key:
                cand.evidence.expected.append(key)
                if cand.evidence.seen[-1] != key:
                    cand.evidence.missed.append(key)

    # ------------------------------------------------------------------ decisions
    def decide(self, reference: ChangeDetector | None = None) -> list[Change]:
        """The confirmed changes (removals, moves, then additions; by instance id / first
        sighting). ``reference``: the detector fed with the city's own drives against the same
        map (module docstring): moves relative to its offsets, removals relative to its misses."""
        out: list[Change] = []
        moves: list[Change] = []
        for i in sorted(self.stored):
            s = self.stored[i]
            ev = s.evidence
            if ev.mostly_missed(self.cfg.remove_frames, self.cfg.remove_share):
                out.append(Change("removed", s.cls, i, s.points, s.closed, ev))
                continue
            ref = reference.stored.get(i) if reference is not None else None
            move = None
            if not s.closed:
                bias = None if ref is None else self._median_offsets(ref)
                move = self._move(i, s, bias)
            if move is not None:
                moves.append(move)
            elif self._missed_more_than(s, ref):
                out.append(Change("removed", s.cls, i, s.points, s.closed, ev))
        out += moves
        for cand in self.candidates:
            ev = cand.evidence
            if len(ev.seen) >= self.cfg.add_frames and len(ev.seen) >= self.cfg.add_share * len(
                ev.expected
            ):
                pts = _candidate_geometry(cand, self.gmap.spacing, self.gmap.smoothing)
                closed = cand.cls == MapClass.PED_CROSSING
                out.append(Change("added", cand.cls, -1, pts, closed, ev, new_points=pts))
        return out

    def _missed_more_than(self, s: Stored, ref: Stored | None) -> bool:
        """Whether ``s`` was missed (nothing within ``remove_gate``) in a share of its frames at
        least ``remove_drop`` (its class's) above the share in which the reference, the same
        detector on the city's own drives, missed it: a detector that still draws a removed line
        in some frames, from the lanes around it, misses it more often than before. The rise
        must also be ``remove_z`` standard errors or more (the pooled two-proportion test): an
        instance in view in a few frames misses a share 0.25 higher by chance."""
        drop = self.cfg.remove_drop[s.cls]
        if ref is None or not np.isfinite(drop):
            return False
        k = self.cfg.remove_frames
        n, m = len(s.evidence.expected), len(ref.evidence.expected)
        if m < k or s.near_missed < k:
            return False
        rise = s.near_missed_share() - ref.near_missed_share()
        pooled = (s.near_missed + ref.near_missed) / (n + m)
        spread = np.sqrt(pooled * (1.0 - pooled) * (1.0 / n + 1.0 / m))  # the rise's std. error
        return rise >= drop and rise >= self.cfg.remove_z * spread

    def _median_offsets(self, s: Stored) -> NDArray[np.float64]:
        """(n,) the median sideways offset of each stored point observed in >= ``move_obs``
        frames (NaN elsewhere)."""
        n = len(s.points)
        med = np.full(n, np.nan)
        if not s.obs_idx:
            return med
        idx = np.concatenate(s.obs_idx)  # (o,)
        off = np.concatenate(s.obs_off)  # (o,)
        count = np.bincount(idx, minlength=n)  # (n,)
        order = np.argsort(idx, kind="stable")
        starts = np.concatenate([[0], np.cumsum(count)])
        sorted_off = off[order]
        for v in np.flatnonzero(count >= self.cfg.move_obs):
            med[v] = np.median(sorted_off[starts[v] : starts[v + 1]])
        return med

    def _move(self, i: int, s: Stored, bias: NDArray[np.float64] | None = None) -> Change | None:
        """A move of stored line ``i``, if any; ``bias`` (n,): the reference's median offset
        per point (NaN: none), taken off the observed offsets."""
        if not s.obs_idx:
            return None
        idx = np.concatenate(s.obs_idx)  # (o,)
        off = np.concatenate(s.obs_off)  # (o,)
        if bias is not None:
            off = off - np.nan_to_num(bias, nan=0.0)[idx]
        n = len(s.points)
        count = np.bincount(idx, minlength=n)  # (n,)
        med = np.zeros(n)  # (n,)
        order = np.argsort(idx, kind="stable")
        starts = np.concatenate([[0], np.cumsum(count)])
        sorted_off = off[order]
        for v in np.flatnonzero(count):
            med[v] = np.median(sorted_off[starts[v] : starts[v + 1]])
        observed = count >= self.cfg.move_obs  # (n,)
        spacing = float(np.median(np.linalg.norm(np.diff(s.points, axis=0), axis=1)))
        need = max(2, int(np.ceil(self.cfg.move_length[s.cls] / max(spacing, 1e-6))))
        runs = []
        for sign in (1.0, -1.0):
            moved = observed & (sign * med >= self.cfg.move_threshold[s.cls])
            runs += [(a, b) for a, b in _runs(moved) if b - a >= need]
        if not runs:
            return None
        in_runs = np.zeros(n, bool)
        for a, b in runs:
            in_runs[a:b] = True
        shift = np.zeros(n)  # (n,) sideways shift of every stored point
        if in_runs.sum() >= 0.6 * observed.sum():  # the whole line moved
            shift[:] = float(np.median(med[in_runs]))
            part = slice(0, n)
        else:
            lo, hi = n, 0
            ramp = int(np.ceil(RAMP / max(spacing, 1e-6)))
            for a, b in runs:
                floor = 0.25 * float(np.abs(med[a:b]).max())  # the ramps down to a quarter
                a0, b0 = a, b
                while a > max(0, a0 - ramp) and observed[a - 1] and abs(med[a - 1]) >= floor:
                    a -= 1
                while b < min(n, b0 + ramp) and observed[b] and abs(med[b]) >= floor:
                    b += 1
                k = np.ones(5) / 5.0
                shift[a:b] = np.convolve(np.pad(med[a:b], 2, mode="edge"), k, mode="valid")
                lo, hi = min(lo, a), max(hi, b)
            part = slice(lo, hi)
        new = s.points + shift[:, None] * s.normals  # (n, 2)
        keys = [k for k, ix in zip(s.obs_keys, s.obs_idx, strict=True) if in_runs[ix].any()]
        ev = Evidence(list(s.evidence.expected), keys, list(s.evidence.missed))
        return Change(
            "moved", s.cls, i, new[part], False, ev, before=s.points[part], new_points=new,
            offset=float(np.median(med[in_runs])),
        )  # fmt: skip


def _candidate_geometry(cand: _Candidate, spacing: float, smoothing: float) -> NDArray[np.float64]:
    """A candidate's geometry: polylines: the engine's merge of its sightings (longest first);
    a crossing: the sighting with the smallest summed Chamfer distance to the others."""
    from icmapper._icmap import GlobalMap, chamfer_distance

    if cand.cls == MapClass.PED_CROSSING:
        rings = cand.sightings
        cost = [sum(chamfer_distance(a, b) for b in rings) for a in rings]
        return np.asarray(rings[int(np.argmin(cost))], np.float64)
    order = sorted(
        range(len(cand.sightings)),
        key=lambda k: -float(np.linalg.norm(np.diff(cand.sightings[k], axis=0), axis=1).sum()),
    )
    m = GlobalMap(smoothing=smoothing, spacing=spacing)
    i = m.insert(cand.cls, cand.sightings[order[0]])
    for k in order[1:]:
        m.merge(i, cand.sightings[k])
    return np.asarray(m.get(i)[1], np.float64)


def mark_map_errors(changes: list[Change], known: list[Change], gate: float = 1.5) -> None:
    """Sets ``cause = "map"`` on the changes that one of ``known`` (what the city's own drives,
    replayed against the map, already disagreed with) explains: the same type and class within
    ``gate`` metres (``update_eval.change_distance``)."""
    from icmapper.city.update_eval import change_distance

    for ch in changes:
        for k in known:
            if k.change == ch.change and k.cls == ch.cls:
                if change_distance(ch.points, ch.closed, k.points, k.closed) <= gate:
                    ch.cause = "map"
                    break


def apply_changes(gmap: GlobalMap, changes: list[Change], drive: int, frame: int = 0) -> None:
    """Applies the confirmed changes of the road (``cause`` "road"; map errors are reported, not
    applied) to ``gmap``: removals removed, moves' geometry replaced,
    additions inserted (their ``instance`` set to the new id); moved and added instances are
    tagged with the drives that saw them (else ``drive``; their provenance). Other instances are
    not touched."""
    for ch in changes:
        if ch.cause != "road":
            continue
        drives = sorted({d for d, _ in ch.evidence.seen}) or [drive]
        if ch.change == "removed":
            gmap.remove(ch.instance)
            continue
        if ch.change == "moved":
            assert ch.new_points is not None
            gmap.replace(ch.instance, ch.new_points, frame)
        elif ch.change == "added":
            ch.instance = gmap.insert(ch.cls, ch.points, frame)
        else:
            raise ValueError(f"unknown change {ch.change!r}")
        for d in drives:
            gmap.tag_drive(d, ids=[ch.instance])
