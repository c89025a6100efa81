"""Geometry engine benchmark (``python -m benchmarks geometry``): prints measured numbers and
ratios (never asserts).

One per-frame workload of the online mapper — query the expanded patch (60 x 30 m range + 20 m
margin), sample 20 points for every instance in it, merge ~30 detections — run with the native
engine (``icmapper.GlobalMap``) and with a plain-Python reference built on shapely (STRtree query,
intersection clipping, interpolation) and scipy (``splprep``/``splev`` merge fit) on identical
inputs, on synthetic city-like maps of 1e2 .. 1e5 instances.
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
# the plain-Python reference (shapely + scipy)


def _patch_polygon(pose: np.ndarray, hx: float, hy: float) -> Any:
    import shapely

    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    corners = [(-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy)]
    return shapely.Polygon([(x + c * u - s * v, y + s * u + c * v) for u, v in corners])


def _to_ego(pts: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """World (..., 2) -> ego (..., 2)."""
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    dx, dy = pts[..., 0] - x, pts[..., 1] - y
    return np.stack([c * dx + s * dy, -s * dx + c * dy], axis=-1)


def _resample_np(pts: np.ndarray, spacing: float, closed: bool) -> np.ndarray:
    """numpy arc-length resampling about ``spacing`` apart (same counts as the engine)."""
    ring = np.vstack([pts, pts[:1]]) if closed else pts  # (m', 2)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(ring, axis=0), axis=1))])
    k = math.ceil(s[-1] / spacing)
    n = max(3, k) if closed else max(2, k + 1)
    t = np.linspace(0.0, s[-1], n, endpoint=not closed)  # (n,)
    return np.stack([np.interp(t, s, ring[:, 0]), np.interp(t, s, ring[:, 1])], axis=1)


class ShapelyMap:
    """Reference global map: shapely geometries, an STRtree built once plus a list of geometries
    changed since (tested exactly on every query), scipy spline merges, shapely union crossings."""

    def __init__(self, instances: dict[int, tuple[int, np.ndarray]]) -> None:
        import shapely
        from scipy.interpolate import splev, splprep  # imported here: not in the timed frames

        self._splprep, self._splev = splprep, splev
        self.cls = {i: c for i, (c, _) in instances.items()}
        self.pts = {i: p for i, (_, p) in instances.items()}
        self.geom = {i: self._make(c, p) for i, (c, p) in instances.items()}
        self.tree_ids = np.array(sorted(instances), dtype=np.int64)
        self.tree = shapely.STRtree([self.geom[int(i)] for i in self.tree_ids])
        self.dirty: set[int] = set()

    @staticmethod
    def _make(cls: int, pts: np.ndarray) -> Any:
        import shapely

        return shapely.Polygon(pts) if cls == CLASS_CROSSING else shapely.LineString(pts)

    def query(self, patch: Any) -> np.ndarray:
        import shapely

        hits = self.tree_ids[self.tree.query(patch, predicate="intersects")]
        ids = {int(i) for i in hits if int(i) not in self.dirty}
        dirty = sorted(self.dirty)
        if dirty:
            inter = shapely.intersects(np.array([self.geom[i] for i in dirty]), patch)
            ids.update(i for i, hit in zip(dirty, inter, strict=True) if hit)
        return np.array(sorted(ids), dtype=np.uint64)

    def sample_patch(
        self, pose: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Same outputs as ``GlobalMap.sample_patch(pose, RANGE, MARGIN, N_POINTS)``."""
        import shapely

        patch = _patch_polygon(pose, RANGE[0] + MARGIN, RANGE[1] + MARGIN)
        ids = self.query(patch)
        k = len(ids)
        pts = np.zeros((k, N_POINTS, 2), dtype=np.float32)  # (k, 20, 2)
        mask = np.zeros((k, N_POINTS), dtype=bool)  # (k, 20)
        cls = np.array([self.cls[int(i)] for i in ids], dtype=np.int64)  # (k,)
        clipped = shapely.intersection(np.array([self.geom[int(i)] for i in ids]), patch)
        for r, (c, geom) in enumerate(zip(cls, clipped, strict=True)):
            parts = shapely.get_parts(geom)
            if c == CLASS_CROSSING:
                polys = [q for q in parts if q.geom_type == "Polygon"]
                if not polys:
                    continue
                ring = max(polys, key=lambda q: q.area).exterior
                d = np.linspace(0.0, ring.length, N_POINTS, endpoint=False)  # (20,)
                world = shapely.get_coordinates(shapely.line_interpolate_point(ring, d))
                mask[r] = True
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
                mask[r, :-1] = piece[:-1] == piece[1:]
            pts[r] = _to_ego(world, pose)
        return ids, cls, pts, mask

    def merge(self, i: int, det: np.ndarray) -> None:
        """Algorithm 2 in plain Python: orient, order along the global line, fit, resample."""
        import shapely

        splprep, splev = self._splprep, self._splev
        cls, glob = self.cls[i], self.pts[i]
        if cls == CLASS_CROSSING:
            union = shapely.union(self.geom[i], shapely.make_valid(shapely.Polygon(det)))
            if union.geom_type != "Polygon":
                union = union.convex_hull
            new = _resample_np(np.asarray(union.exterior.coords)[:-1], SPACING, closed=True)
        else:
            g_dir, d_dir = glob[-1] - glob[0], det[-1] - det[0]
            if float(g_dir @ d_dir) < 0:
                det = det[::-1]
            line = self.geom[i]
            length = line.length
            # extended arc-length parameter along the global line (beyond the ends: signed)
            t = shapely.line_locate_point(line, shapely.points(det))  # (d,)
            u0 = (glob[1] - glob[0]) / np.linalg.norm(glob[1] - glob[0])
            u1 = (glob[-1] - glob[-2]) / np.linalg.norm(glob[-1] - glob[-2])
            before = t <= 1e-9
            after = t >= length - 1e-9
            t = t.copy()
            t[before] = (det[before] - glob[0]) @ u0
            t[after] = length + (det[after] - glob[-1]) @ u1
            tg = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(glob, axis=0), axis=1))])
            allp = np.vstack([glob, det])  # (m + d, 2)
            allt = np.concatenate([tg, t])  # (m + d,)
            order = np.argsort(allt, kind="stable")
            pts = allp[order]
            keep = np.concatenate([[True], np.linalg.norm(np.diff(pts, axis=0), axis=1) > 1e-6])
            pts = pts[keep]
            tck, _ = splprep([pts[:, 0], pts[:, 1]], s=SMOOTHING, k=min(3, len(pts) - 1))
            dense = np.stack(splev(np.linspace(0.0, 1.0, 4 * len(pts)), tck), axis=1)
            new = _resample_np(dense, SPACING, closed=False)
        self.pts[i] = new
        self.geom[i] = self._make(cls, new)
        self.dirty.add(i)


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
        "the two maps' merged geometry drifts apart by centimetres)"
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
