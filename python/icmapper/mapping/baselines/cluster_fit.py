"""Cluster & Fit: an offline mapping baseline.

`step` only collects: every detected instance of the sequence, in the world frame, per class, as
points `spacing` apart along it (so that the density DBSCAN sees does not depend on the detector's
20-point sampling). `finish`
builds the map: per class, DBSCAN (eps 3 m, min 5 samples: the paper's setting) over the points;
per cluster, a polyline (dividers, boundaries) is ordered along the cluster's principal axis —
points binned every `spacing` metres along it, one mean point per bin — and fitted with the
engine's smoothing spline (`icmapper.geom.fit_curve`); a crossing is the convex hull of its
cluster. Ordering by the principal axis assumes a cluster that does not fold back on itself
(U-shapes are flattened): one of the weaknesses of this baseline, as is the merging of touching
instances of one class into one cluster.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import ConvexHull, QhullError, cKDTree

from icmapper.data.types import NUM_CLASSES, Frame, MapClass
from icmapper.mapping.baselines.common import Baseline, new_global_map
from icmapper.mapping.methods import MethodInfo, register_method
from icmapper.mapping.types import StepResult

if TYPE_CHECKING:
    from icmapper._icmap import GlobalMap


def dbscan(points: NDArray[np.floating], eps: float, min_samples: int) -> NDArray[np.int64]:
    """DBSCAN (Ester et al. 1996, sklearn semantics: a core point has >= min_samples points,
    itself included, within eps).

    points (n, 2) -> labels (n,) int64: cluster index 0.. in order of first appearance, -1 for
    noise.
    A border point reachable from several clusters joins the one of its nearest core neighbour.
    """
    p = np.asarray(points, dtype=np.float64)
    n = p.shape[0]
    labels = np.full(n, -1, np.int64)
    if n == 0:
        return labels
    tree = cKDTree(p)
    pairs = tree.query_pairs(eps, output_type="ndarray")  # (e, 2) i < j
    counts = 1 + np.bincount(pairs.ravel(), minlength=n)  # (n,) neighbours incl. itself
    core = counts >= min_samples  # (n,)
    cc = pairs[core[pairs[:, 0]] & core[pairs[:, 1]]]  # core-core links
    graph = coo_matrix((np.ones(len(cc)), (cc[:, 0], cc[:, 1])), shape=(n, n))
    _, comp = connected_components(graph, directed=False)  # (n,)
    labels[core] = comp[core]
    # Border points: nearest core neighbour within eps.
    border = np.nonzero(~core)[0]
    if border.size and core.any():
        core_idx = np.nonzero(core)[0]
        d, j = cKDTree(p[core_idx]).query(p[border], distance_upper_bound=eps)
        ok = np.isfinite(d)
        labels[border[ok]] = comp[core_idx[j[ok]]]
    # Renumber 0.. in order of first appearance.
    out = np.full(n, -1, np.int64)
    seen: dict[int, int] = {}
    for i, lab in enumerate(labels.tolist()):
        if lab >= 0:
            out[i] = seen.setdefault(lab, len(seen))
    return out


def densify(points: NDArray[np.floating], spacing: float, closed: bool) -> NDArray[np.float64]:
    """Points about `spacing` apart along a polyline (n, 2) (with its closing edge if closed),
    vertices kept -> (m, 2). Makes the clustering independent of how sparsely a detector samples."""
    from icmapper.geom import arc_lengths, points_at_lengths

    p = np.asarray(points, dtype=np.float64)
    q = np.concatenate([p, p[:1]]) if closed else p
    s = arc_lengths(q)  # (e + 1,)
    t = np.union1d(np.arange(0.0, s[-1], spacing), s[:-1] if closed else s)  # (m,)
    return points_at_lengths(q, t)  # (m, 2)


def order_along_axis(points: NDArray[np.floating], spacing: float) -> NDArray[np.float64]:
    """A cluster (c, 2) -> ordered centreline (b, 2): the mean point of each `spacing`-wide bin
    along the principal axis, in axis order (empty bins skipped)."""
    p = np.asarray(points, dtype=np.float64)
    centre = p.mean(axis=0)  # (2,)
    _, _, vt = np.linalg.svd(p - centre, full_matrices=False)
    u = (p - centre) @ vt[0]  # (c,) coordinate along the principal axis
    bins = np.floor((u - u.min()) / spacing).astype(np.int64)  # (c,)
    nb = int(bins.max()) + 1
    cnt = np.bincount(bins, minlength=nb)  # (nb,)
    sx = np.bincount(bins, weights=p[:, 0], minlength=nb)
    sy = np.bincount(bins, weights=p[:, 1], minlength=nb)
    ok = cnt > 0
    return np.stack([sx[ok] / cnt[ok], sy[ok] / cnt[ok]], axis=1)  # (b, 2)


class ClusterFit(Baseline):
    """Cluster & Fit (offline; see the module docstring).

    source: detections; score_threshold: detections below are ignored; eps / min_samples: DBSCAN;
    smoothing: curve-fit smoothing s (scipy splprep semantics); spacing: bin width along the axis
    and the map's point spacing.
    """

    name = "cluster-fit"

    def setup(self) -> None:
        cfg = self.config
        self.eps = cfg.cluster_eps
        self.min_samples = cfg.cluster_min_samples
        self.smoothing = cfg.smoothing
        self.spacing = cfg.spacing
        self._points: list[list[NDArray[np.float64]]] = [[] for _ in range(NUM_CLASSES)]
        self._last_frame = 0

    def reset(self) -> None:
        self.source.reset()
        self._points = [[] for _ in range(NUM_CLASSES)]
        self._last_frame = 0

    def step(self, frame: Frame) -> StepResult:
        """Collects the frame's detected points (world frame); builds nothing."""
        inp = self.read(frame)
        for i in range(len(inp.dets)):
            cls = int(inp.dets.classes[i])
            pts = densify(inp.world[i], self.spacing, MapClass(cls).closed)  # (m, 2)
            self._points[cls].append(pts)
        self._last_frame = max(self._last_frame, frame.index)
        k = len(inp.dets)
        return StepResult(frame.index, inp.dets, np.full(k, -1, np.int64), inp.dets.points.copy())

    def finish(self) -> GlobalMap:
        """Clusters everything collected and returns a new global map."""
        from icmapper.geom import fit_curve

        gmap = new_global_map(self.config)
        for cls in range(NUM_CLASSES):
            if not self._points[cls]:
                continue
            pts = np.concatenate(self._points[cls])  # (N, 2)
            labels = dbscan(pts, self.eps, self.min_samples)  # (N,)
            for lab in range(int(labels.max()) + 1):
                cluster = pts[labels == lab]  # (c, 2)
                if MapClass(cls).closed:
                    try:
                        hull = ConvexHull(cluster)
                    except QhullError:
                        continue  # degenerate (collinear) cluster: no area, no crossing
                    gmap.insert(cls, cluster[hull.vertices], self._last_frame)  # CCW ring
                    continue
                line = order_along_axis(cluster, self.spacing)  # (b, 2)
                if line.shape[0] < 2:
                    continue  # a point-like cluster has no polyline
                if line.shape[0] >= 4:
                    line = fit_curve(line, s=self.smoothing, spacing=self.spacing)
                gmap.insert(cls, line, self._last_frame)
        return gmap


register_method(
    MethodInfo(
        ClusterFit.name,
        "Cluster & Fit: DBSCAN of all detected points, spline fit / convex hull",
        build=ClusterFit,
    )
)
