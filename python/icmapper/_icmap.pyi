"""Typed stub of the native extension ``icmapper._icmap`` (Rust crate ``icmap-py``).

Conventions: metres and radians; points are ``(n, 2)`` array-likes of a real dtype (float64 and
float32 arrays are read without conversion, integer arrays and nested sequences are converted);
results are float64 unless stated. A ``pose`` is ``(x, y, yaw)`` ego -> world, ``half_extents`` is
``(hx, hy)`` along the ego x / y axes. Classes: 0 ped_crossing (closed ring, first point not
repeated), 1 divider, 2 boundary (open polylines).

Coordinate domain: every coordinate (points, the ``x``, ``y`` of a pose, stored map files) is
finite with ``|x|, |y| <= 1e7`` m, and half extents and margins are at most 1e7 m; ``yaw`` is any
finite angle. Anything outside raises ``ValueError`` (naming the value) at the call, instead of
computing overflowed, infinite or NaN results; inside it every result is finite.

Errors: ``ValueError`` for bad values (NaN/inf, too few points, degenerate geometry, bad
parameters, unknown class, wrong shapes, duplicate id, corrupt map file), ``TypeError`` for wrong
types/dtypes (complex, object, str), ``KeyError`` for an unknown instance id, ``OSError`` (with the
path as ``filename``; ``FileNotFoundError`` for a missing file) for I/O failures. Integer arguments
(counts, ``cls``, ``frame``) take Python or numpy ints; one that does not fit in 64 bits raises
``ValueError`` naming the argument. Heavy work runs with the GIL released.
"""

import os
from collections.abc import Sequence
from typing import Any, TypedDict

import numpy as np
import numpy.typing as npt

__version__: str

ArrayLike2 = npt.ArrayLike  # (n, 2) real coordinates
Pose = Sequence[float] | npt.NDArray[np.floating[Any]]  # (x, y, yaw)
Extents = Sequence[float] | npt.NDArray[np.floating[Any]]  # (hx, hy)
F64 = npt.NDArray[np.float64]
PathArg = str | os.PathLike[str]

def resample(points: ArrayLike2, n: int, closed: bool = False) -> F64:
    """Exactly ``n`` points evenly spaced by arc length.

    points: (m, 2), m >= 2. Open: first and last point kept, ``n >= 2``. Closed: ``n >= 3`` points
    along the contour including the closing edge, starting at the first point, not repeated.
    ``n`` is at most 10,000,000 (the output is allocated up front). Returns (n, 2) float64.
    ValueError on NaN/inf, fewer than 2 points, zero length or bad ``n``.
    """

def resample_spacing(points: ArrayLike2, spacing: float = 1.0, closed: bool = False) -> F64:
    """Points about ``spacing`` metres apart by arc length.

    points: (m, 2). Returns (k, 2) float64 with ``k = max(2, ceil(L / spacing) + 1)`` for an open
    polyline (ends kept) and ``k = max(3, ceil(L / spacing))`` for a closed contour. ValueError
    as ``resample``, for a non-finite or non-positive ``spacing``, and when ``k`` would exceed
    10,000,000.
    """

def clip_to_patch(
    points: ArrayLike2,
    pose: Pose,
    half_extents: Extents,
    margin: float = 0.0,
    closed: bool = False,
) -> list[F64]:
    """The parts of ``points`` inside the oriented patch of ``pose`` (half extents + margin).

    points: (m, 2) in the same frame as ``pose`` (usually world); the result is in that frame too.
    Open polyline: the pieces inside the patch in the polyline's order, each (k_i, 2), k_i >= 2,
    entry/exit points exact. Closed ring (``closed=True``, m >= 3): ``[ring]`` with the clipped
    ring (k, 2) without a repeated first point, or ``[]`` when the ring lies outside.
    """

def fit_curve(points: ArrayLike2, s: float = 0.5, spacing: float = 1.0) -> F64:
    """Smoothing parametric cubic spline (scipy ``splprep(s=s, k=3)`` semantics) of ``points``.

    points: (m, 2), m >= 2 distinct points (degree drops to m - 1 for 2 or 3 points). Returns the
    fitted curve evaluated about ``spacing`` metres apart, ends included: (k, 2) float64.
    ``s``: finite, >= 0 (0 interpolates every point); ``spacing``: finite, > 0; ValueError
    otherwise, and when the curve would need 10,000,000 points or more.
    """

def merge_polyline(
    global_pts: ArrayLike2, detected_pts: ArrayLike2, s: float = 0.5, spacing: float = 1.0
) -> F64:
    """Merges a detected polyline into a global one (IC-Mapper Algorithm 2), both world frame.

    global_pts: (m, 2), detected_pts: (d, 2). The detection's orientation is decided from the
    geometry; the detection and the global points within 5 m of it (by arc length) are fitted
    (``fit_curve`` with ``s``) and resampled about ``spacing`` apart; the global points beyond
    are kept as they are. The result keeps the global direction: (k, 2) float64. ``s`` and
    ``spacing`` as for ``fit_curve``.
    """

def splice_polyline(stored: ArrayLike2, new: ArrayLike2, overlap: float) -> F64:
    """Splices a new open polyline into a stored one by projection (the rule of IC-Mapper's fused
    polylines and of the VMA / PolyMerge baselines).

    stored (m, 2), new (q, 2), both with >= 2 points, one frame. ``new`` is oriented like
    ``stored``; stored points within ``overlap`` metres of ``new`` are substituted by it; the stored
    points before the projection of new's start and after the projection of its end are kept.
    Returns (r, 2) float64. ValueError for too few points, NaN/inf or out-of-domain coordinates and
    an ``overlap`` that is not finite and >= 0.
    """

def polygon_union(rings: Sequence[ArrayLike2] | npt.NDArray[np.floating[Any]]) -> list[F64]:
    """Union of closed rings (each (n_i, 2) without a repeated first point, or an (R, n, 2) array).

    Returns the outer rings of the union (holes dropped), counter-clockwise, largest area first;
    several rings when the union falls apart. Each ring (k, 2) float64, first point not repeated.
    Every input ring needs at least 3 points; a ring of zero area (also one so small that its
    area underflows) contributes nothing, so all-degenerate input gives ``[]``.
    """

def chamfer_distance(a: ArrayLike2, b: ArrayLike2) -> float:
    """Chamfer distance (mean nearest distance a->b + mean nearest distance b->a) / 2.

    a: (n, 2), b: (m, 2), both non-empty and finite.
    """

def chamfer_matrix(
    a: Sequence[ArrayLike2] | npt.NDArray[np.floating[Any]],
    b: Sequence[ArrayLike2] | npt.NDArray[np.floating[Any]],
) -> F64:
    """All pairwise Chamfer distances: (A, B) float64.

    a: an (A, n, 2) array or a list of A arrays (n_i, 2); b likewise with B sets.
    """

def vectorise(
    prob: npt.NDArray[np.float32],
    half_x: float,
    half_y: float,
    *,
    upsample: int = 4,
    threshold: float = 0.5,
    min_length: float = 2.0,
    min_area: float = 2.0,
    shrink: float = 0.9,
    rectangularity: float = 0.6,
    corner_tolerance: float = 2.0,
    hull_simplify: float = 0.5,
    max_hole: float = 2.0,
    simplify: float = 0.2,
    through: float = 45.0,
    spur: float = 4.0,
    ridge_classes: Sequence[int] = (1,),
    ridge_threshold: float = 0.3,
    ridge_sigma: float = 0.6,
    ridge_curvature: float = 0.22,
    num_points: int = 20,
    edge_margin: float = 1.5,
    edge_span: float = 3.0,
    bend: float = 45.0,
    band: float = 1.8,
    parallel: bool = True,
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float32], npt.NDArray[np.float32]]:
    """Map instances of one frame from the segmentation's class probabilities (the vectoriser).

    prob: (K, X, Y) float32 class probabilities on the BEV grid, X cells along ego x over
    ``[-half_x, half_x]``, Y along ego y (metres); class 0 (crossing) gives closed contours, the
    others open polylines. The settings are ``icmapper.models.vectorise.VectoriseParams``' (the
    Python ``vectorise`` passes them): bilinear upsampling, thresholds, the ridge mask of
    ``ridge_classes``, skeleton branches joined through junctions (``through`` degrees) with spurs
    under ``spur`` metres dropped (the kerbs of a band two kerbs wide, ``band``: its shrunk
    outline's), simplified, ridge lines cut where they turn by more than ``bend`` degrees,
    resampled to ``num_points``, ridge lines along the front or back edge of the grid
    (``edge_margin``, ``edge_span``) dropped; crossing masks cut into one part per crossing,
    outlined and shrunk. ``parallel``: the classes at once on the engine's thread pool (same
    result). Returns ``(classes (N,) int64, scores (N,) float32 (mean probability of the
    instance's cells), points (N, num_points, 2) float32 ego metres)``, classes in index order.
    ValueError on an empty axis, NaN/inf probabilities or extents, bad settings (as
    ``VectoriseParams``) or an upsampled grid beyond 2**26 cells; TypeError for another dtype or
    number of axes. Runs with the GIL released.
    """

class InstanceInfo(TypedDict):
    id: int
    cls: int
    closed: bool
    first_frame: int
    last_frame: int
    observations: int
    n_points: int
    drives: list[int]  # ascending ids of the drives that observed the instance (provenance)

class MergeMapStats(TypedDict):
    merged: int  # instances of ``other`` merged into instances of this map
    inserted: int  # instances of ``other`` inserted with fresh ids
    absorbed: int  # instances of this map joined into another of this map (removed)

class GlobalMap:
    """The global vector map (world frame): instances, bookkeeping and a spatial index.

    Thread-safe: one map may be used from several Python threads (a read-write lock inside; the
    GIL is released while it is held). Never pickled: use ``save`` / ``load``.
    """

    def __init__(self, smoothing: float = 0.5, spacing: float = 1.0) -> None:
        """An empty map; ``smoothing``: the curve-fit ``s`` on merge, finite and >= 0 (0: merged
        polylines interpolate every point, scipy's ``s=0``); ``spacing``: metres between stored
        points, finite and > 0. ValueError otherwise (negative or non-finite ``smoothing``,
        non-positive or non-finite ``spacing``)."""

    @property
    def smoothing(self) -> float:
        """The curve-fit smoothing ``s`` used on merge."""

    @property
    def spacing(self) -> float:
        """Spacing of the stored dense points, metres."""

    def __len__(self) -> int: ...
    def __contains__(self, id: object) -> bool: ...
    def insert(self, cls: int, points: ArrayLike2, frame: int = 0) -> int:
        """Inserts a new instance of class ``cls`` (0, 1, 2), points (n, 2) world frame, observed
        at ``frame``; returns its id (assigned increasingly from 0, never reused)."""

    def insert_with_id(self, id: int, cls: int, points: ArrayLike2, frame: int = 0) -> None:
        """Inserts with a caller-chosen id; ValueError if the id already exists."""

    def merge(self, id: int, points: ArrayLike2, frame: int = 0) -> None:
        """Merges a detection (n, 2) world frame into instance ``id`` by its class rule (curve fit
        for polylines, union for crossings). KeyError for an unknown id; on error the instance is
        unchanged. A small merge (stored plus detected points <= 512: microseconds of work) runs
        with the GIL held when no other thread holds the map; other merges release the GIL."""

    def merge_many(
        self,
        ids: Sequence[int] | npt.NDArray[np.integer[Any]],
        points: Sequence[ArrayLike2] | npt.NDArray[np.floating[Any]],
        frame: int = 0,
    ) -> list[KeyError | ValueError | None]:
        """Merges ``points[i]`` (n_i, 2) world frame into instance ``ids[i]`` for every i, at
        ``frame``. The map is exactly the one of calling ``merge`` for each item in order (items
        for the same instance apply in order); the merges of different instances run in parallel
        with the GIL released (the calling thread and a pool of its own; ``RAYON_NUM_THREADS``
        sets the number of threads, 1 merges on the calling thread only). Returns per item None,
        or the exception ``merge`` would have raised for it (KeyError for an unknown id,
        ValueError for bad geometry); a failed item changes nothing and does not affect the
        others. TypeError/ValueError are raised before any merge for malformed arguments (not a
        sequence, different lengths, wrong shapes)."""

    def replace(self, id: int, points: ArrayLike2, frame: int = 0) -> None:
        """Replaces the geometry of instance ``id`` with ``points`` (n, 2) world frame (resampled at
        ``spacing``) as a new observation at ``frame``: first frame kept, last frame and
        observation count updated. For merge rules implemented outside the store (baselines).
        KeyError for an unknown id; ValueError for bad geometry (the instance is unchanged)."""

    def trim(self, id: int, start: int, stop: int) -> None:
        """Cuts the polyline instance ``id`` to its stored points ``[start, stop)`` (no
        resampling; first and last frame and observation count unchanged): a clean-up of a
        finished map (``mapping.verify``). KeyError for an unknown id; ValueError for a crossing
        or a range out of bounds or of fewer than 2 points (the instance is unchanged)."""

    def splice(self, id: int, points: ArrayLike2, overlap: float = 0.5, frame: int = 0) -> None:
        """Splices the open polyline ``points`` (n, 2) world frame into instance ``id``
        (``splice_polyline(stored, points, overlap)``), resampled at ``spacing``, as a new
        observation at ``frame`` (as ``replace``). KeyError for an unknown id; ValueError for a
        crossing instance, bad geometry or a bad ``overlap`` (the instance is unchanged)."""

    def remove(self, id: int) -> None:
        """Removes instance ``id``; KeyError if absent."""

    def get(self, id: int) -> tuple[int, F64]:
        """``(cls, points (n, 2) float64)`` of instance ``id``; KeyError if absent."""

    def info(self, id: int) -> InstanceInfo:
        """Bookkeeping of instance ``id`` (with ``drives``, its provenance); KeyError if absent."""

    def tag_drive(self, drive: int, ids: Sequence[int] | None = None) -> None:
        """Records that drive ``drive`` (an int in 0..2**32 - 1; ValueError outside) observed every
        instance now in the map, or only the instances ``ids`` (KeyError for an unknown id; then
        nothing changes): ``info(id)["drives"]`` then contains it."""

    def merge_map(
        self,
        other: GlobalMap,
        gate: float = 1.5,
        min_overlap: float = 0.5,
        tolerance: float = 3.0,
    ) -> MergeMapStats:
        """Merges every instance of ``other`` into this map; ``other`` is unchanged.

        Candidates: the instances of this map (as it was before the call) of the same class whose
        bounding box meets the other instance's box grown by ``gate`` (the spatial index). Overlap
        test: with ``s(B, A)`` the share of B's points within ``gate`` metres of A's geometry (its
        polyline; for a crossing its ring, 0 inside), A and B overlap when ``max(s(B, A),
        s(A, B)) >= min_overlap``. Each connected group of overlapping instances becomes one
        instance (an instance of ``other`` overlapping two of this map joins them; two of
        ``other`` are joined only through one of this map), merged from its largest member in
        breadth-first order of the overlaps (larger share, then smaller mean distance, then lower
        id) by the class rules: the curve-fit merge (``merge_polyline`` with this map's smoothing
        and spacing) for polylines, polygon union for crossings. A polyline merge is kept only
        when every vertex of both members lies within ``tolerance`` metres of the result and
        every vertex of the result within ``tolerance`` of a member (nothing lost, nothing
        invented such as a jump between far-apart pieces), and at most 6 m of either member
        lies farther than ``gate`` from it (the two sides of a median island, overlapping within
        the gate, are not merged into one line); the merge of the second into the
        first is tried, then of the first into the second; if neither holds, the member is left
        out of the group (an instance of this map stays as it was, one of ``other`` is
        inserted). The group keeps the lowest id of its
        instances of this map; its drives are the union, its observations the sum, its first /
        last frame the min / max of its members'. The other instances of ``other`` are inserted
        with fresh ids (ascending id order of ``other``), geometry and bookkeeping copied.
        Deterministic; the order in which drive maps are merged changes the result only within
        the drives' disagreement (tested: map Chamfer per class <= 0.25 m for drives offset by
        up to 0.14 m). ValueError for ``gate`` not finite or < 0, ``min_overlap`` outside (0, 1],
        ``tolerance`` not finite or <= 0;
        TypeError if ``other`` is not a GlobalMap. The GIL is released (the overlap tests and
        the groups' merges run in parallel)."""

    def absorb(
        self,
        ids: Sequence[int],
        gate: float = 1.0,
        min_overlap: float = 0.5,
        tolerance: float = 3.0,
    ) -> list[tuple[int, int]]:
        """Absorbs duplicates around the instances ``ids`` (unknown ids skipped): an instance
        overlapping a same-class neighbour (the overlap test of ``merge_map``: the larger of the
        two shares of points within ``gate`` metres of the other, at least ``min_overlap``)
        becomes part of it. Of a pair the instance with more points keeps its id (ties: the
        lower id) and takes the other's geometry by ``merge_map``'s class rule (a polyline merge
        only when faithful within ``tolerance`` and ``gate``, crossings by union); observations
        add up, frames span both, drives are the union; the other is removed. Neighbours are
        tried by larger share, smaller mean distance, lower id; a keeper is checked again.
        Returns the ``(absorbed, into)`` pairs in the order they happened (follow chains).
        Deterministic. ValueError for bad parameters (as ``merge_map``); the GIL is released."""

    def ids(self) -> npt.NDArray[np.uint64]:
        """All instance ids, ascending: (k,) uint64."""

    def query(
        self, pose: Pose, half_extents: Extents, margin: float = 0.0
    ) -> npt.NDArray[np.uint64]:
        """Ids (ascending, (k,) uint64) of the instances whose geometry intersects the oriented
        patch of ``pose`` with half extents ``half_extents + margin``."""

    def sample_patch(
        self,
        pose: Pose,
        half_extents: Extents,
        margin: float = 20.0,
        n_points: int = 20,
    ) -> tuple[
        npt.NDArray[np.uint64],
        npt.NDArray[np.int64],
        npt.NDArray[np.float32],
        npt.NDArray[np.bool_],
    ]:
        """Every instance in the expanded patch, clipped to it and sampled to ``n_points``.

        Returns ``(ids (k,) uint64, cls (k,) int64, pts (k, n_points, 2) float32, mask
        (k, n_points) bool)``; ``pts`` in the EGO frame of ``pose``; ``mask[i, j]``: point j
        connects to point j + 1 on the same clipped piece (for a crossing clipped to a single
        ring the last entry is True). k = 0 gives empty arrays of these shapes. ``n_points``:
        2 to 1,000,000 (at least 3 when a crossing is sampled); ValueError otherwise.
        """

    def save(self, path: PathArg, compact: bool = False) -> None:
        """Writes the native map file (format 2) atomically (temp file ``.NAME.tmp.<pid>.<n>`` +
        rename); OSError on I/O failure. ``compact=False`` stores coordinates bit for bit;
        ``compact=True`` rounds them to a 0.1 mm grid (a loaded coordinate is at most 0.05 mm off)
        and delta-codes them: about a fifth of the size for densely sampled polylines. Provenance
        is kept either way. A writer killed mid-save leaves the map file intact (old or new); the
        temp files of dead writers are removed by the next save into the same folder (each writer
        holds a lock on its temp file, so a live writer's is never removed)."""

    @staticmethod
    def load(path: PathArg, bbox: tuple[float, float, float, float] | None = None) -> GlobalMap:
        """Reads a map file (format 1 or 2); ValueError naming the file if it is not a valid map
        file (wrong magic, truncated, corrupt), OSError (FileNotFoundError) if it cannot be read.
        With ``bbox = (xmin, ymin, xmax, ymax)``: only the instances whose bounding box meets it
        (a format-2 file's index says which blocks to read; the rest of the file is not read, a
        format-1 file is read whole); ValueError for NaN or min > max."""

    def to_bytes(self, compact: bool = False) -> bytes:
        """The native map file's contents in memory (``save``'s bytes)."""

    @staticmethod
    def from_bytes(data: bytes | bytearray) -> GlobalMap:
        """A map from map file contents (format 1 or 2); ValueError if they are not valid."""

    def to_geojson(self, path: PathArg) -> None:
        """Writes the map as a GeoJSON FeatureCollection (atomically)."""
