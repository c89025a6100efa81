"""Geometry engine benchmark (``python -m benchmarks geometry``): prints measured numbers and
ratios (never asserts).

One per-frame workload of the online mapper — query the expanded patch (60 x 30 m range + 20 m
margin), sample 20 points for every instance in it, merge ~30 detections — run with the native
engine (``icmapper.GlobalMap``) and with a plain-Python reference built on shapely (STRtree query,
intersection clipping, interpolation) and scipy (``splprep``/``splev`` merge fit) on identical
inputs, on synthetic city-like maps of 1e2 .. 1e5 instances.

The reference makes the engine's algorithmic choices, so that the ratio measures the
implementation and not the algorithm: its STRtree holds the instances' boxes grown by 1 m and is
rebuilt by the engine's rule (``ShapelyMap``), candidates come by box and are clipped, and a merge
refits only the detection and 5 m of the instance on either side (``FIT_CONTEXT``), splicing the
detection in place of the part it overlaps, as ``crates/icmap-geom/src/merge.rs`` does.
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import math
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

RANGE = (30.0, 15.0)  # half extents of the 60 x 30 m perception range
MARGIN = 20.0
N_POINTS = 20
N_DETECTIONS = 30
SMOOTHING, SPACING = 0.5, 1.0
CLASS_CROSSING = 0


def city_instances(n: int, seed: int) -> list[tuple[int, np.ndarray]]:
    """A synthetic city-like map of exactly ``n`` instances (world frame, metres).

    A square grid of streets 100 m apart; every street has two boundaries (class 2, +-7 m) and a
    divider (class 1) split into 30-60 m instances with a gentle wiggle, and every junction four
    crossings (class 0, 4 x 14 m rectangles). The grid is the smallest one with >= n instances; a
    seeded random subset of n is kept. Returns ``[(cls, points (m, 2))]``.
    """
    rng = np.random.default_rng(seed)
    g = max(2, math.ceil(math.sqrt(n / 17.0)))
    block, size = 100.0, g * 100.0
    out: list[tuple[int, np.ndarray]] = []
    for axis in (0, 1):
        for k in range(g):
            c = (k + 0.5) * block
            for off, cls in ((-7.0, 2), (0.0, 1), (7.0, 2)):
                s = 0.0
                while size - s > 5.0:
                    e = min(size, s + float(rng.uniform(30.0, 60.0)))
                    t = np.linspace(s, e, max(2, int((e - s) / 5.0) + 1))  # (m,)
                    w = c + off + 0.3 * np.sin(t / 17.0 + k)  # (m,)
                    pts = np.stack([t, w], axis=1) if axis == 0 else np.stack([w, t], axis=1)
                    out.append((cls, pts))
                    s = e
    box = np.array([[-2.0, -7.0], [2.0, -7.0], [2.0, 7.0], [-2.0, 7.0]])  # (4, 2)
    for i in range(g):
        for j in range(g):
            cx, cy = (i + 0.5) * block, (j + 0.5) * block
            for dx, dy, rot in ((-11, 0, False), (11, 0, False), (0, -11, True), (0, 11, True)):
                b = box[:, ::-1] if rot else box
                out.append((CLASS_CROSSING, b + [cx + dx, cy + dy]))
    keep = np.sort(rng.choice(len(out), size=min(n, len(out)), replace=False))
    return [out[i] for i in keep]


def random_poses(instances: list[tuple[int, np.ndarray]], frames: int, seed: int) -> np.ndarray:
    """Ego poses (frames, 3) on random polylines of the map, heading along them."""
    rng = np.random.default_rng(seed)
    lines = [p for c, p in instances if c != CLASS_CROSSING]
    poses = np.zeros((frames, 3))
    for f in range(frames):
        p = lines[int(rng.integers(len(lines)))]
        j = int(rng.integers(len(p) - 1))
        d = p[j + 1] - p[j]
        yaw = math.atan2(d[1], d[0]) + (math.pi if rng.random() < 0.5 else 0.0)
        poses[f] = (*(p[j] + rng.uniform(0, 1) * d), yaw + rng.normal(0, 0.05))
    return poses


def detections_for(
    gm: Any, pose: np.ndarray, rng: np.random.Generator
) -> list[tuple[int, np.ndarray]]:
    """~30 noisy detections of instances in the 60 x 30 m range: ``[(id, points (20, 2))]``.

    Each is the instance clipped to the range, resampled to 20 points, plus N(0, 0.1 m) noise.
    """
    from icmapper import geom

    ids = gm.query(pose, RANGE)
    out: list[tuple[int, np.ndarray]] = []
    if len(ids) == 0:
        return out
    for i in rng.choice(ids, size=N_DETECTIONS, replace=len(ids) < N_DETECTIONS):
        cls, pts = gm.get(int(i))
        closed = cls == CLASS_CROSSING
        pieces = geom.clip_to_patch(pts, pose, RANGE, closed=closed)
        if not pieces:
            continue
        piece = max(pieces, key=lambda q: float(np.linalg.norm(np.diff(q, axis=0), axis=1).sum()))
        try:
            det = geom.resample(piece, N_POINTS, closed=closed)  # (20, 2)
        except ValueError:  # a clipped sliver of zero length
            continue
        out.append((int(i), det + rng.normal(0.0, 0.1, det.shape)))
    return out


# ---------------------------------------------------------------------------------------------
# the plain-Python reference (shapely + scipy; the patch and the ego frame:
# icmapper.testing.geom_reference)


def _resample_np(pts: np.ndarray, spacing: float, closed: bool) -> np.ndarray:
    """numpy arc-length resampling about ``spacing`` apart (same counts as the engine)."""
    ring = np.vstack([pts, pts[:1]]) if closed else pts  # (m', 2)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(ring, axis=0), axis=1))])
    k = math.ceil(s[-1] / spacing)
    n = max(3, k) if closed else max(2, k + 1)
    t = np.linspace(0.0, s[-1], n, endpoint=not closed)  # (n,)
    return np.stack([np.interp(t, s, ring[:, 0]), np.interp(t, s, ring[:, 1])], axis=1)


#: The engine's index (``crates/icmap-geom/src/index.rs``): boxes in the tree are the exact ones
#: grown by LOOSE_MARGIN m, and the tree is rebuilt once the changes it does not hold exceed
#: max(REBUILD_MIN, live / 2).
LOOSE_MARGIN, REBUILD_MIN = 1.0, 64
#: The engine's merge (``crates/icmap-geom/src/merge.rs``): metres of the stored polyline on either
#: side of the detection that are fitted again with it; points farther away are kept.
FIT_CONTEXT = 5.0


def _dedup(pts: np.ndarray, eps: float = 1e-9) -> np.ndarray:
    """Drops points closer than ``eps`` to the previous one (as the engine's ``dedup``)."""
    keep = np.concatenate([[True], np.linalg.norm(np.diff(pts, axis=0), axis=1) > eps])
    return pts[keep]


class ShapelyMap:
    """Reference global map in plain Python with the engine's algorithmic choices: shapely
    geometries; an STRtree over the instances' boxes grown by LOOSE_MARGIN, rebuilt as the
    engine's tree is (an update whose box still fits in its loose box leaves the tree alone; the
    others are kept aside and tested by their boxes until the tree is rebuilt, once they exceed
    max(REBUILD_MIN, live / 2)); candidates by box, then clipped (empty clips dropped); merges
    that refit only the detection and FIT_CONTEXT m of the instance on either side (scipy
    ``splprep``), crossings by shapely union."""

    def __init__(self, instances: dict[int, tuple[int, np.ndarray]]) -> None:
        from scipy.interpolate import splev, splprep  # imported here: not in the timed frames

        self._splprep, self._splev = splprep, splev
        self.ids = np.array(sorted(instances), dtype=np.uint64)  # (N,) slot -> id
        self.slot = {int(i): k for k, i in enumerate(self.ids)}
        self.cls = np.array([instances[int(i)][0] for i in self.ids], dtype=np.int64)  # (N,)
        self.pts = [instances[int(i)][1] for i in self.ids]
        self.geom = [self._make(int(c), p) for c, p in zip(self.cls, self.pts, strict=True)]
        self.bounds = np.array([self._bounds(p) for p in self.pts])  # (N, 4) exact boxes
        self.loose = self.bounds + [-LOOSE_MARGIN, -LOOSE_MARGIN, LOOSE_MARGIN, LOOSE_MARGIN]
        self.aside: set[int] = set()  # slots whose box left the tree's loose box
        self.rebuilds = 0
        self._rebuild()
        self.rebuilds = 0  # the first build is part of the set-up

    @staticmethod
    def _make(cls: int, pts: np.ndarray) -> Any:
        import shapely

        return shapely.Polygon(pts) if cls == CLASS_CROSSING else shapely.LineString(pts)

    @staticmethod
    def _bounds(pts: np.ndarray) -> np.ndarray:
        return np.concatenate([pts.min(axis=0), pts.max(axis=0)])  # (4,) xmin ymin xmax ymax

    def _rebuild(self) -> None:
        import shapely

        self.tree = shapely.STRtree(shapely.box(*self.loose.T))
        self.aside.clear()
        self.rebuilds += 1

    def _update(self, k: int, pts: np.ndarray) -> None:
        """Stores slot ``k``'s new points and keeps the index as the engine's ``upsert`` does."""
        self.pts[k] = pts
        self.geom[k] = self._make(int(self.cls[k]), pts)
        b = self._bounds(pts)
        self.bounds[k] = b
        lo = self.loose[k]
        if lo[0] <= b[0] and lo[1] <= b[1] and b[2] <= lo[2] and b[3] <= lo[3]:
            return  # still inside the tree's loose box
        self.loose[k] = b + [-LOOSE_MARGIN, -LOOSE_MARGIN, LOOSE_MARGIN, LOOSE_MARGIN]
        self.aside.add(k)
        if len(self.aside) > max(REBUILD_MIN, len(self.ids) // 2):
            self._rebuild()

    def candidates(self, patch: Any) -> np.ndarray:
        """Slots (ascending) whose exact box meets the patch's box, as the engine's ``query``."""
        xmin, ymin, xmax, ymax = patch.bounds
        hits = self.tree.query(patch.envelope)  # loose boxes of the last build
        if self.aside:
            hits = np.union1d(hits, np.fromiter(self.aside, dtype=np.int64, count=len(self.aside)))
        b = self.bounds[hits]  # (h, 4)
        keep = (b[:, 0] <= xmax) & (b[:, 2] >= xmin) & (b[:, 1] <= ymax) & (b[:, 3] >= ymin)
        return np.sort(hits[keep])

    def sample_patch(
        self, pose: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Same outputs as ``GlobalMap.sample_patch(pose, RANGE, MARGIN, N_POINTS)``."""
        import shapely
        from icmapper.testing.geom_reference import patch_polygon, to_ego

        patch = patch_polygon(pose, RANGE[0] + MARGIN, RANGE[1] + MARGIN)
        slots = self.candidates(patch)
        clipped = shapely.intersection(np.array([self.geom[k] for k in slots]), patch)
        rows: list[tuple[int, np.ndarray, np.ndarray]] = []  # (slot, world (20, 2), mask (20,))
        for k, geom in zip(slots, clipped, strict=True):
            parts = shapely.get_parts(geom)
            mask = np.zeros(N_POINTS, dtype=bool)  # (20,)
            if self.cls[k] == CLASS_CROSSING:
                polys = [q for q in parts if q.geom_type == "Polygon" and not q.is_empty]
                if not polys:
                    continue  # the clip is empty: not in the patch
                ring = max(polys, key=lambda q: q.area).exterior
                d = np.linspace(0.0, ring.length, N_POINTS, endpoint=False)  # (20,)
                world = shapely.get_coordinates(shapely.line_interpolate_point(ring, d))
                mask[:] = True
            else:
                lines = [q for q in parts if q.geom_type == "LineString" and q.length > 0]
                if not lines:
                    continue
                lengths = np.array([q.length for q in lines])  # (p,)
                d = np.linspace(0.0, lengths.sum(), N_POINTS)  # (20,)
                starts = np.concatenate([[0.0], np.cumsum(lengths)[:-1]])  # (p,)
                piece = np.clip(np.searchsorted(starts, d, side="right") - 1, 0, len(lines) - 1)
                geoms = np.array(lines, dtype=object)[piece]  # (20,)
                world = shapely.get_coordinates(
                    shapely.line_interpolate_point(geoms, d - starts[piece])
                )
                mask[:-1] = piece[:-1] == piece[1:]
            rows.append((int(k), world, mask))
        ids = np.array([self.ids[k] for k, _, _ in rows], dtype=np.uint64)  # (k,)
        cls = np.array([self.cls[k] for k, _, _ in rows], dtype=np.int64)  # (k,)
        pts = np.zeros((len(rows), N_POINTS, 2), dtype=np.float32)  # (k, 20, 2)
        mask = np.zeros((len(rows), N_POINTS), dtype=bool)  # (k, 20)
        for r, (_, world, m) in enumerate(rows):
            pts[r], mask[r] = to_ego(world, pose), m
        return ids, cls, pts, mask

    def _fit(self, pts: np.ndarray) -> np.ndarray:
        """Smoothing spline through ``pts`` (scipy ``splprep``, s = SMOOTHING), resampled
        about SPACING apart."""
        pts = _dedup(pts)
        tck, _ = self._splprep([pts[:, 0], pts[:, 1]], s=SMOOTHING, k=min(3, len(pts) - 1))
        dense = np.stack(self._splev(np.linspace(0.0, 1.0, 4 * len(pts)), tck), axis=1)
        return _resample_np(dense, SPACING, closed=False)

    def _merge_polyline(self, k: int, det: np.ndarray) -> np.ndarray:
        """The engine's polyline merge in plain Python: the detection located along the stored
        polyline (arc length, extended beyond the ends), oriented by the tangents, spliced in
        place of the part it overlaps; the detection and FIT_CONTEXT m of stored points on either
        side fitted again, the points beyond kept as they are."""
        import shapely

        g, d = _dedup(self.pts[k]), _dedup(det)
        cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(g, axis=0), axis=1))])
        seg = np.diff(g, axis=0) / np.diff(cum)[:, None]  # (m - 1, 2) unit tangents
        t = shapely.line_locate_point(self.geom[k], shapely.points(d))  # (d,) in [0, L]
        before, after = t <= 1e-9, t >= cum[-1] - 1e-9
        t = t.copy()
        t[before] = (d[before] - g[0]) @ seg[0]
        t[after] = cum[-1] + (d[after] - g[-1]) @ seg[-1]
        j = np.clip(np.searchsorted(cum, t, side="right") - 1, 0, len(seg) - 1)  # (d,)
        tangent = seg[j]  # (d, 2)
        score = float(np.sum(np.diff(d, axis=0) * (tangent[:-1] + tangent[1:])))
        if score < 0 or (score == 0 and t[-1] < t[0]):
            d, t = d[::-1], t[::-1]
        lo, hi = t.min() - 0.5 * SPACING, t.max() + 0.5 * SPACING
        window = np.vstack(
            [
                g[(cum < lo) & (cum >= lo - FIT_CONTEXT)],
                d,
                g[(cum > hi) & (cum <= hi + FIT_CONTEXT)],
            ]
        )
        kept_before, kept_after = g[cum < lo - FIT_CONTEXT], g[cum > hi + FIT_CONTEXT]
        fitted = self._fit(window)
        if len(kept_before) == 0 and len(kept_after) == 0:
            return fitted
        joined = _dedup(np.vstack([kept_before[-1:], fitted, kept_after[:1]]))
        return np.vstack(
            [kept_before[:-1], _resample_np(joined, SPACING, closed=False), kept_after[1:]]
        )

    def merge(self, i: int, det: np.ndarray) -> None:
        """Merges a detection into instance ``i`` (Algorithm 2, the engine's rules)."""
        import shapely

        k = self.slot[i]
        if self.cls[k] == CLASS_CROSSING:
            union = shapely.union(self.geom[k], shapely.make_valid(shapely.Polygon(det)))
            if union.geom_type != "Polygon":
                union = union.convex_hull  # the hull of both rings, as the engine's
            new = _resample_np(np.asarray(union.exterior.coords)[:-1], SPACING, closed=True)
        else:
            new = self._merge_polyline(k, det)
        self._update(k, new)


# ---------------------------------------------------------------------------------------------
# runner


@dataclass
class SizeResult:
    n: int
    engine_ms: float
    """Per frame with one ``GlobalMap.merge`` call per detection."""
    batched_ms: float
    """Per frame with one ``GlobalMap.merge_many`` call for all detections of the frame."""
    reference_ms: float | None
    mean_k: float
    ids_agree: str
    engine_sample_ms: float
    reference_sample_ms: float | None


def _engine_map(instances: list[tuple[int, np.ndarray]]) -> Any:
    from icmapper import GlobalMap

    gm = GlobalMap(smoothing=SMOOTHING, spacing=SPACING)
    for f, (cls, pts) in enumerate(instances):
        gm.insert(cls, pts, frame=f)
    return gm


@contextlib.contextmanager
def _no_gc() -> Iterator[None]:
    """Python's cyclic garbage collector off for a timed section (as ``timeit`` does): with 1e5
    instances the set-up keeps millions of objects alive, and a full collection landing inside a
    timed frame would be charged to whichever side happened to allocate."""
    gc.collect()
    gc.disable()
    try:
        yield
    finally:
        gc.enable()


def _time_engine(
    instances: list[tuple[int, np.ndarray]],
    poses: np.ndarray,
    dets: list[list[tuple[int, np.ndarray]]],
    batched: bool,
) -> tuple[float, float, list[list[int]], Any]:
    """One timed pass over the frames on a fresh map: (ms per frame, of which sample_patch,
    the sampled ids per frame, the map)."""
    gm = _engine_map(instances)
    batch_in = [([i for i, _ in det], [d for _, d in det]) for det in dets]
    ids_per_frame: list[list[int]] = []
    t_sample = 0.0
    with _no_gc():
        t0 = time.perf_counter()
        for pose, det, (det_ids, det_pts) in zip(poses, dets, batch_in, strict=True):
            t1 = time.perf_counter()
            ids, _cls, _pts, _mask = gm.sample_patch(pose, RANGE, margin=MARGIN, n_points=N_POINTS)
            t_sample += time.perf_counter() - t1
            if batched:
                gm.merge_many(det_ids, det_pts, frame=1)
            else:
                for i, d in det:
                    gm.merge(i, d, frame=1)
            ids_per_frame.append(ids.tolist())
        total = time.perf_counter() - t0
    return total / len(poses) * 1e3, t_sample / len(poses) * 1e3, ids_per_frame, gm


def _time_reference(
    start: dict[int, tuple[int, np.ndarray]],
    poses: np.ndarray,
    dets: list[list[tuple[int, np.ndarray]]],
) -> tuple[float, float, list[list[int]]]:
    """One timed pass of the shapely/scipy reference on a fresh copy of the start map."""
    ref = ShapelyMap(start)
    ids_per_frame: list[list[int]] = []
    t_sample = 0.0
    with _no_gc():
        t0 = time.perf_counter()
        for pose, det in zip(poses, dets, strict=True):
            t1 = time.perf_counter()
            ids, _cls, _pts, _mask = ref.sample_patch(pose)
            t_sample += time.perf_counter() - t1
            for i, d in det:
                ref.merge(i, d)
            ids_per_frame.append(ids.tolist())
        total = time.perf_counter() - t0
    return total / len(poses) * 1e3, t_sample / len(poses) * 1e3, ids_per_frame


def _bench_size(n: int, frames: int, ref_frames: int, seed: int, rounds: int = 5) -> SizeResult:
    """Best of ``rounds`` timed passes of each side (each on a fresh map, the same frames), as
    ``timeit`` reports: the machine's hiccups only ever add time. The passes are interleaved
    (engine, engine with ``merge_many``, reference; then again), so that a slow spell of a shared
    machine falls on both sides rather than on whichever side happened to run then."""
    instances = city_instances(n, seed)
    poses = random_poses(instances, frames, seed + 1)
    rng = np.random.default_rng(seed + 2)
    probe = _engine_map(instances)
    dets = [detections_for(probe, pose, rng) for pose in poses]
    # identical start for the reference: the engine's stored geometry
    start = {int(i): probe.get(int(i)) for i in probe.ids()}
    del probe

    m = min(ref_frames, frames)
    engine, batched, refs = [], [], []
    for _ in range(rounds):
        engine.append(_time_engine(instances, poses, dets, batched=False))
        batched.append(_time_engine(instances, poses, dets, batched=True))
        if m > 0:
            refs.append(_time_reference(start, poses[:m], dets[:m]))
    seq_map, bat_map = engine[0][3], batched[0][3]
    for i in (int(j) for j in seq_map.ids()[:: max(1, len(seq_map) // 50)]):
        if seq_map.get(i)[1].tobytes() != bat_map.get(i)[1].tobytes():
            raise RuntimeError(f"merge_many and merge disagree on instance {i}")
    engine_ids = engine[0][2]
    best = min(engine, key=lambda r: r[0])

    reference_ms, reference_sample_ms, agree = None, None, "-"
    if refs:
        ref_best = min(refs, key=lambda r: r[0])
        reference_ms, reference_sample_ms = ref_best[0], ref_best[1]
        same = sum(a == b for a, b in zip(refs[0][2], engine_ids[:m], strict=True))
        agree = f"{same}/{m}"
    return SizeResult(
        n,
        best[0],
        min(r[0] for r in batched),
        reference_ms,
        float(np.mean([len(ids) for ids in engine_ids])),
        agree,
        best[1],
        reference_sample_ms,
    )


def add_geometry_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--sizes",
        type=int,
        nargs="+",
        default=[100, 1_000, 10_000, 100_000],
        help="map sizes (instances)",
    )
    parser.add_argument("--frames", type=int, default=200, help="frames timed per size (engine)")
    parser.add_argument(
        "--ref-frames",
        type=int,
        default=200,
        help="frames timed per size (shapely/scipy; the first ones of the engine's frames)",
    )
    parser.add_argument(
        "--rounds",
        type=int,
        default=5,
        help="timed passes per side, interleaved between the sides; the best one is reported",
    )
    parser.add_argument("--seed", type=int, default=0)


def run_geometry(args: argparse.Namespace) -> int:
    """Runs the geometry benchmark and prints a table of per-frame times and ratios.

    BLAS runs single-threaded meanwhile: neither side calls BLAS in the timed frames, but
    OpenBLAS's idle worker threads spin after numpy's set-up work and would take the CPU that
    ``merge_many``'s threads need.
    """
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        return _run_geometry(args)


def _run_geometry(args: argparse.Namespace) -> int:
    import os

    print(
        f"per-frame workload: sample_patch (range {2 * RANGE[0]:.0f}x{2 * RANGE[1]:.0f} m + "
        f"{MARGIN:.0f} m margin, {N_POINTS} points/instance) + ~{N_DETECTIONS} merges "
        f"(s={SMOOTHING}, spacing={SPACING} m)"
    )
    print(
        "times per frame; 'merge': one GlobalMap.merge call per detection (one thread); "
        "'merge_many': one call per frame, instances merged in parallel "
        f"({os.cpu_count()} CPUs); 'sample' = the query + clip + sample part alone; "
        f"each side: best of {max(1, args.rounds)} passes (interleaved) on a fresh map; "
        "'ids agree': frames "
        "where both sampled the same instance ids (later frames can differ at the patch border: "
        "the two maps' merged geometry drifts apart by centimetres); the reference makes the "
        f"engine's choices: STRtree of boxes grown by {LOOSE_MARGIN:.0f} m rebuilt by the engine's "
        f"rule, candidates by box then clipped, merges refitting +-{FIT_CONTEXT:.0f} m around the "
        "detection"
    )
    print(
        f"{'instances':>10} {'in patch':>9} {'shapely ms':>11} {'merge ms':>9} {'ratio':>7} "
        f"{'merge_many ms':>14} {'ratio':>7} {'sample ms':>10} {'shapely ms':>11} {'ratio':>7} "
        f"{'ids agree':>10}"
    )

    def ratio(ref: float | None, ours: float) -> str:
        return f"{ref / ours:6.1f}x" if ref is not None else f"{'-':>7}"

    results: list[SizeResult] = []
    for n in args.sizes:
        r = _bench_size(n, args.frames, args.ref_frames, args.seed, max(1, args.rounds))
        results.append(r)
        ref = f"{r.reference_ms:11.2f}" if r.reference_ms is not None else f"{'-':>11}"
        sref = (
            f"{r.reference_sample_ms:11.2f}" if r.reference_sample_ms is not None else f"{'-':>11}"
        )
        print(
            f"{r.n:>10} {r.mean_k:9.1f} {ref} {r.engine_ms:9.3f} "
            f"{ratio(r.reference_ms, r.engine_ms)} {r.batched_ms:14.3f} "
            f"{ratio(r.reference_ms, r.batched_ms)} {r.engine_sample_ms:10.3f} {sref} "
            f"{ratio(r.reference_sample_ms, r.engine_sample_ms)} {r.ids_agree:>10}",
            flush=True,
        )
    by_n = {r.n: r for r in results}
    if 1_000 in by_n and 100_000 in by_n:
        scale = by_n[100_000].engine_ms / by_n[1_000].engine_ms
        scale_b = by_n[100_000].batched_ms / by_n[1_000].batched_ms
        print(
            f"engine time at 1e5 / at 1e3: merge {scale:.2f}, merge_many {scale_b:.2f} "
            "(target <= 1.5)"
        )
    done = [r for r in results if r.reference_ms is not None]
    if done:
        seq = min(r.reference_ms / r.engine_ms for r in done if r.reference_ms is not None)
        bat = min(r.reference_ms / r.batched_ms for r in done if r.reference_ms is not None)
        print(
            f"speed-up over shapely/scipy: min {seq:.1f}x with merge, {bat:.1f}x with "
            "merge_many (target >= 30x)"
        )
    return 0


def main(argv: list[str] | None = None) -> int:
    """``python -m benchmarks geometry [options]``: the geometry benchmark."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks geometry", description=__doc__)
    add_geometry_arguments(parser)
    return run_geometry(parser.parse_args(argv))
