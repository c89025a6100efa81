"""Track ids re-derived from per-frame predictions the way MapTracker's C-mAP tool does it
(numpy + Pillow, no I/O).

Followed: woodfrog/maptracker at ee8321f, ``tools/tracking/prepare_pred_tracks.py`` and
``tools/tracking/cmap_utils/{match_utils,utils}.py`` (our own implementation). Per sequence:

1. predictions with score **strictly above** ``score_threshold`` (0.4) are kept, each resampled to
   20 points at ``linspace(0, L, 20)`` along the line (shapely ``interpolate``; a crossing along
   its closed ring);
2. frame 0: every kept prediction gets a new id (counted per class);
3. frame t: for each earlier frame p in ``t - look_back .. t - 1`` (``--cons_frames``, default 5),
   p's kept predictions are warped into frame t (SE(3) ``inv(pose_t) @ pose_p``), clamped to the
   perception range, and rasterised with frame t's on a 200 x 100 canvas (``canvas_size``):
   polylines with OpenCV ``polylines(thickness=3)`` on integer-truncated pixel coordinates,
   crossings as filled polygons (Pillow ``ImageDraw.polygon``); a mask under 20 pixels is dilated
   with the 7 x 7 ellipse. Per class, the Hungarian assignment maximising the summed mask IoU
   pairs p's and t's predictions; a pair counts when its IoU > 0.001;
4. ids from the nearest earlier frame first: a prediction takes the id of its match in frame
   t - 1, else t - 2, ... (an id already taken in frame t is skipped); the rest get new ids.

Deviation: OpenCV is not a dependency, so thick polylines are rasterised here as the pixels whose
centre lies within ``LINE_RADIUS`` of the truncated polyline (OpenCV fills a rotated rectangle
per segment plus round joins); docs/eval.md gives the measured agreement with OpenCV's masks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

#: MapTracker's defaults (configs: canvas_size, thickness; prepare_pred_tracks.py: --thr,
#: --cons_frames; find_matchings_iou(thresh=0.001)).
CANVAS = (200, 100)  # (width along x, height along y)
THICKNESS = 3
SCORE_THRESHOLD = 0.4
LOOK_BACK = 5
IOU_THRESHOLD = 0.001
SMALL_MASK = 20
#: Pixels whose centre is within this distance (pixels) of a polyline are drawn: OpenCV's
#: thickness 3 fills a band of half-width 2 with diamond joins (measured in docs/eval.md).
LINE_RADIUS = 2.0
#: cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (7, 7)).
ELLIPSE_7 = np.array(
    [
        [0, 0, 0, 1, 0, 0, 0],
        [0, 1, 1, 1, 1, 1, 0],
        [1, 1, 1, 1, 1, 1, 1],
        [1, 1, 1, 1, 1, 1, 1],
        [1, 1, 1, 1, 1, 1, 1],
        [0, 1, 1, 1, 1, 1, 0],
        [0, 0, 0, 1, 0, 0, 0],
    ],
    dtype=bool,
)


def interp_fixed_num(points: NDArray[np.floating], num: int, closed: bool) -> NDArray[np.float64]:
    """``num`` points at ``linspace(0, L, num)`` along the polyline (both ends included); a closed
    ring is walked back to its first point (MapTracker's ``interp_fixed_num`` of a closed
    LineString). (n, 2) -> (num, 2) float64."""
    from icmapper import geom

    pts = np.asarray(points, dtype=np.float64)  # (n, 2)
    if closed:
        pts = np.concatenate([pts, pts[:1]])  # (n + 1, 2)
    length = geom.arc_lengths(pts)[-1]
    return geom.points_at_lengths(pts, np.linspace(0.0, length, num))  # (num, 2)


def dilate(mask: NDArray[np.bool_], kernel: NDArray[np.bool_] = ELLIPSE_7) -> NDArray[np.bool_]:
    """Binary dilation of (H, W) by a centred odd kernel (cv2.dilate, border pixels not grown
    from outside)."""
    kh, kw = kernel.shape
    ph, pw = kh // 2, kw // 2
    padded = np.pad(mask, ((ph, ph), (pw, pw)))  # (H + kh - 1, W + kw - 1)
    out = np.zeros_like(mask)
    h, w = mask.shape
    for dy, dx in zip(*np.nonzero(kernel), strict=True):
        out |= padded[dy : dy + h, dx : dx + w]
    return out


@dataclass(frozen=True)
class Raster:
    """The canvas of one perception range: ego metres -> pixel coordinates."""

    half_x: float
    half_y: float
    canvas: tuple[int, int] = CANVAS

    def pixels(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """(n, 2) ego metres -> (n, 2) pixel coordinates (column along x, row along y)."""
        w, h = self.canvas
        scale = np.array([w / (2 * self.half_x), h / (2 * self.half_y)])
        return (points + np.array([self.half_x, self.half_y])) * scale  # (n, 2)

    def clamp(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """Points clamped to the perception range (MapTracker clips warped vectors to [0, 1] in
        normalised coordinates)."""
        lim = np.array([self.half_x, self.half_y])
        return np.clip(points, -lim, lim)

    def polyline(self, points: NDArray[np.float64]) -> NDArray[np.bool_]:
        """(n, 2) ego metres -> (H, W) mask of the thick polyline (``LINE_RADIUS``)."""
        w, h = self.canvas
        px = np.trunc(self.pixels(points))  # (n, 2) np.int32(...) truncates toward zero
        mask = np.zeros((h, w), dtype=bool)
        reach = int(np.ceil(LINE_RADIUS))
        for p, q in zip(px[:-1], px[1:], strict=True):
            x0, y0 = np.minimum(p, q).astype(int) - reach
            x1, y1 = np.maximum(p, q).astype(int) + reach
            x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, w - 1), min(y1, h - 1)
            if x0 > x1 or y0 > y1:
                continue
            gx, gy = np.meshgrid(np.arange(x0, x1 + 1), np.arange(y0, y1 + 1))  # window
            d = q - p
            dd = float(d @ d)
            if dd == 0.0:
                u = np.zeros(gx.shape)
            else:
                u = np.clip(((gx - p[0]) * d[0] + (gy - p[1]) * d[1]) / dd, 0.0, 1.0)
            dist2 = (gx - p[0] - u * d[0]) ** 2 + (gy - p[1] - u * d[1]) ** 2  # window
            mask[y0 : y1 + 1, x0 : x1 + 1] |= dist2 <= LINE_RADIUS**2
        return mask

    def polygon(self, points: NDArray[np.float64]) -> NDArray[np.bool_]:
        """(n, 2) ego metres ring -> (H, W) mask: Pillow's filled polygon with outline, as
        MapTracker's ``draw_polygons``."""
        from PIL import Image, ImageDraw

        w, h = self.canvas
        px = self.pixels(points)  # (n, 2)
        verts = [(float(x), float(y)) for x, y in px]
        if not np.array_equal(px[0], px[-1]):
            verts.append(verts[0])
        img = Image.new("L", (w, h), 0)
        ImageDraw.Draw(img).polygon(verts, outline=1, fill=1)
        return np.asarray(img, dtype=np.uint8) > 0

    def mask(self, points: NDArray[np.float64], closed: bool) -> NDArray[np.bool_]:
        """One instance's (20, 2) line (crossings: closed ring with the repeat) -> (H, W)
        mask, dilated when smaller than ``SMALL_MASK`` pixels."""
        m = self.polygon(points) if closed else self.polyline(points)
        if int(m.sum()) < SMALL_MASK:
            m = dilate(m)
        return m


def mask_iou(a: NDArray[np.bool_], b: NDArray[np.bool_]) -> NDArray[np.float64]:
    """(n, P) and (m, P) flattened masks -> (n, m) IoU (0 where the union is empty)."""
    af, bf = a.astype(np.float32), b.astype(np.float32)
    inter = af @ bf.T  # (n, m)
    union = af.sum(1)[:, None] + bf.sum(1)[None, :] - inter  # (n, m)
    return np.where(inter > 0, inter / np.maximum(union, 1.0), 0.0).astype(np.float64)


def match_masks(src: NDArray[np.bool_], tgt: NDArray[np.bool_]) -> NDArray[np.int64]:
    """Per target row the matched source row or -1: Hungarian on -IoU, pairs with IoU above
    ``IOU_THRESHOLD`` (``find_matchings_iou``). src (n, P), tgt (m, P) -> (m,) int64."""
    out = np.full(tgt.shape[0], -1, dtype=np.int64)
    if src.shape[0] == 0 or tgt.shape[0] == 0:
        return out
    iou = mask_iou(src, tgt)  # (n, m)
    rows, cols = linear_sum_assignment(-iou)
    for i, j in zip(rows, cols, strict=True):
        if iou[i, j] > IOU_THRESHOLD:
            out[j] = i
    return out


def derive_track_ids(
    frames: list[tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.floating]]],
    poses: NDArray[np.float64],
    half_extents: tuple[float, float],
    score_threshold: float = SCORE_THRESHOLD,
    look_back: int = LOOK_BACK,
) -> list[NDArray[np.int64]]:
    """MapTracker's re-derived track ids of one sequence (module docstring).

    frames[t] = (classes (k,), scores (k,), points (k, n, 2) ego; crossings as rings without the
    repeated first point); poses (T, 4, 4) ego->world. Returns per frame (k,) int64: the id of
    every prediction (ids count per class, so equal ids of different classes are different
    tracks), -1 for those at or below ``score_threshold``.
    """
    raster = Raster(*half_extents)
    num_cls = 3
    counters = [0] * num_cls
    lines: list[list[NDArray[np.float64]]] = []  # per frame, kept predictions' 20-point lines
    rows: list[list[NDArray[np.int64]]] = []  # per frame and class: rows of the kept predictions
    ids_by_cls: list[list[NDArray[np.int64]]] = []  # per frame and class: ids of those rows
    out = []
    for t, (classes, scores, points) in enumerate(frames):
        classes = np.asarray(classes, dtype=np.int64)
        keep = np.asarray(scores, dtype=np.float64) > score_threshold  # (k,)
        rows_t = [np.flatnonzero(keep & (classes == c)) for c in range(num_cls)]
        line_t = {
            int(r): interp_fixed_num(points[r], 20, classes[r] == 0) for r in np.flatnonzero(keep)
        }
        masks_t = [
            _masks(raster, [line_t[int(r)] for r in rows_t[c]], c == 0) for c in range(num_cls)
        ]
        ids_t: list[NDArray[np.int64]] = []
        for c in range(num_cls):
            n = rows_t[c].size
            if t == 0:
                ids = np.arange(counters[c], counters[c] + n, dtype=np.int64)
                counters[c] += n
                ids_t.append(ids)
                continue
            # candidate ids from each earlier frame, farthest first (as tmp_ids_list)
            cands = []
            for p in range(max(t - look_back, 0), t):
                rel = np.linalg.inv(poses[t]) @ poses[p]  # (4, 4) frame p -> frame t
                warped = [
                    raster.clamp(_apply(rel, lines[p][int(r)])) for r in rows[p][c]
                ]  # list of (20, 2)
                match = match_masks(_masks(raster, warped, c == 0), masks_t[c])  # (n,)
                prev_ids = np.concatenate([ids_by_cls[p][c], [-1]])  # (n_p + 1,): -1 = none
                cands.append(prev_ids[match])
            ids_t.append(_assign(cands, n, counters, c))
        ids_full = np.full(classes.shape[0], -1, dtype=np.int64)
        for c in range(num_cls):
            ids_full[rows_t[c]] = ids_t[c]
        lines.append([line_t.get(j, np.zeros((0, 2))) for j in range(classes.shape[0])])
        rows.append(rows_t)
        ids_by_cls.append(ids_t)
        out.append(ids_full)
    return out


def _apply(rel: NDArray[np.float64], pts: NDArray[np.float64]) -> NDArray[np.float64]:
    """(4, 4) SE(3) applied to (n, 2) points at z = 0 -> (n, 2)."""
    homo = np.concatenate([pts, np.zeros((len(pts), 1)), np.ones((len(pts), 1))], axis=1)
    return (homo @ rel.T)[:, :2]  # (n, 2)


def _masks(raster: Raster, lines: list[NDArray[np.float64]], closed: bool) -> NDArray[np.bool_]:
    """Lines -> (n, H*W) flattened masks."""
    w, h = raster.canvas
    if not lines:
        return np.zeros((0, w * h), dtype=bool)
    return np.stack([raster.mask(ln, closed).ravel() for ln in lines])


def _assign(cands: list[NDArray[np.int64]], n: int, counters: list[int], c: int) -> NDArray:
    """prepare_pred_tracks.get_scene_matching_result's id assignment for one class: candidate
    ids per earlier frame (farthest first), taken nearest first; unassigned rows get new ids."""
    ids: dict[int, int] = {}
    missing: list[int] = []
    for cand in cands[::-1]:
        for j in range(n):
            glb = int(cand[j])
            if j in ids:
                continue
            if glb != -1 and glb not in ids.values():
                ids[j] = glb
                if j in missing:
                    missing.remove(j)
            else:
                missing.append(j)
    for j in missing:
        if j not in ids:
            ids[j] = counters[c]
            counters[c] += 1
    return np.array([ids[j] for j in range(n)], dtype=np.int64)
