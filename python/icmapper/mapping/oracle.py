"""The oracle detection source: ground truth with controlled noise.

It stands in for the learned detector so that association and merging can be tested and compared
on their own. Per frame, each ground-truth instance of the perception range is, in this order,
dropped (missed detection), truncated to a random sub-range of its arc length (partial visibility;
open polylines only), shifted by a per-instance offset and jittered point by point; a Poisson number
of false detections is added; every detection gets a noisy score; an optional pose error moves the
whole frame rigidly (localisation error); the detections are shuffled.

Noise is drawn from a generator seeded by (seed, frame index): the same frame always gives the
same detections, whatever the order frames are asked in. `Detections.gt_ids` carries the true
identity (-1 for false detections) for tests and analysis; methods never read it.
"""

from __future__ import annotations

from collections.abc import Sequence as SequenceOf
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from icmapper import geom
from icmapper.data.types import (
    NUM_INSTANCE_POINTS,
    Frame,
    FrameGT,
    MapClass,
    PerceptionRange,
    RANGE_60x30,
    Sequence,
)
from icmapper.mapping.types import Detections


@dataclass(frozen=True)
class OracleNoise:
    """How the oracle corrupts ground truth (all distances in metres, per frame).

    jitter_std: std of independent Gaussian noise on every point (x and y).
    offset_std: std of a Gaussian translation shared by all points of one instance.
    drop_rate: probability that a true instance is missed.
    partial_rate: probability that an open polyline is seen only on a random sub-range of its arc
        length, of fraction uniform in [partial_min, 1) (crossings are never truncated).
    false_rate: mean number of false detections per frame (Poisson); each is a random short line
        (divider or boundary) or a small rectangle (crossing) inside the range.
    score_true / score_false: mean score of true / false detections; score_std: std of the
        Gaussian score noise (scores clipped to [0, 1]); with overlap when score_std is large.
    pose_xy_std / pose_yaw_std: std of a per-frame rigid error applied to all detections
        (localisation error; metres / radians).
    """

    jitter_std: float = 0.15
    offset_std: float = 0.0
    drop_rate: float = 0.1
    partial_rate: float = 0.1
    partial_min: float = 0.5
    false_rate: float = 0.05
    score_true: float = 0.85
    score_false: float = 0.4
    score_std: float = 0.1
    pose_xy_std: float = 0.0
    pose_yaw_std: float = 0.0

    def __post_init__(self) -> None:
        for name in (
            "jitter_std",
            "offset_std",
            "false_rate",
            "score_std",
            "pose_xy_std",
            "pose_yaw_std",
        ):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"OracleNoise.{name} must be finite and >= 0, got {v}")
        for name in ("drop_rate", "partial_rate", "score_true", "score_false"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"OracleNoise.{name} must be in [0, 1], got {v}")
        if not 0.0 < self.partial_min <= 1.0:
            raise ValueError(f"OracleNoise.partial_min must be in (0, 1], got {self.partial_min}")

    @staticmethod
    def preset(name: str) -> OracleNoise:
        """Named noise levels: "none" (exact ground truth, score 1), "low", "medium", "high"."""
        try:
            return _PRESETS[name]
        except KeyError:
            raise ValueError(
                f"unknown oracle noise preset {name!r}; one of {sorted(_PRESETS)}"
            ) from None


# The named noise levels as a table, one row each; the columns are OracleNoise's fields in order:
# jitter_std, offset_std, drop_rate, partial_rate, partial_min, false_rate, score_true,
# score_false, score_std, pose_xy_std, pose_yaw_std.
_PRESETS: dict[str, OracleNoise] = {
    name: OracleNoise(*row)
    for name, row in {
        "none": (0.0, 0.0, 0.0, 0.0, 0.5, 0.0, 1.0, 0.4, 0.0, 0.0, 0.0),
        "low": (0.1, 0.0, 0.05, 0.05, 0.5, 0.05, 0.85, 0.4, 0.1, 0.0, 0.0),
        "medium": (0.2, 0.1, 0.1, 0.15, 0.5, 0.3, 0.85, 0.4, 0.15, 0.0, 0.0),
        "high": (0.4, 0.3, 0.25, 0.3, 0.5, 1.0, 0.7, 0.5, 0.2, 0.2, 0.005),
    }.items()
}


def _sub_range(points: NDArray[np.float64], a: float, b: float, n: int) -> NDArray[np.float64]:
    """The part of an open polyline (m, 2) between arc-length fractions a < b, as (n, 2) points
    evenly spaced by arc length."""
    total = geom.arc_lengths(points)[-1]
    return geom.points_at_lengths(points, np.linspace(a * total, b * total, n))  # (n, 2)


def _false_instance(
    rng: np.random.Generator, prange: PerceptionRange, n: int
) -> tuple[int, NDArray[np.float64]]:
    """A random false detection inside the range: (class, (n, 2) ego points)."""
    cls = int(rng.integers(0, 3))
    centre = rng.uniform([-prange.half_x, -prange.half_y], [prange.half_x, prange.half_y])  # (2,)
    yaw = rng.uniform(-np.pi, np.pi)
    rot = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
    if cls == MapClass.PED_CROSSING:
        w, h = rng.uniform(2.0, 4.0), rng.uniform(5.0, 12.0)
        corners = np.array([[-w, -h], [w, -h], [w, h], [-w, h]]) / 2.0  # (4, 2)
        # Points evenly along the closed contour.
        ring = np.concatenate([corners, corners[:1]])  # (5, 2)
        total = geom.arc_lengths(ring)[-1]
        local = geom.points_at_lengths(ring, np.linspace(0.0, total, n, endpoint=False))  # (n, 2)
    else:
        length = rng.uniform(5.0, 25.0)
        bend = rng.normal(0.0, 0.02)
        u = np.linspace(-length / 2, length / 2, n)
        local = np.stack([u, bend * u**2], axis=1)  # (n, 2)
    pts = local @ rot.T + centre  # (n, 2)
    lo = np.array([-prange.half_x, -prange.half_y])
    return cls, np.clip(pts, lo, -lo)


class OracleDetector:
    """A DetectionSource made of a sequence's ground truth with controlled noise.

    sequence: the sequence whose frames are asked for (`detect(frame)` reads frame.index);
    rng: perception range; noise: an OracleNoise or a preset name; seed: the noise seed;
    gt: per-frame ground truth (len(sequence) FrameGTs); computed with
    icmapper.data.gt.sequence_gt(sequence, rng) on first use when omitted.
    """

    def __init__(
        self,
        sequence: Sequence,
        rng: PerceptionRange = RANGE_60x30,
        noise: OracleNoise | str = OracleNoise(),
        seed: int = 0,
        gt: SequenceOf[FrameGT] | None = None,
    ) -> None:
        self.sequence = sequence
        self.range = rng
        self.noise = OracleNoise.preset(noise) if isinstance(noise, str) else noise
        self.seed = int(seed)
        if gt is not None and len(gt) != len(sequence):
            raise ValueError(
                f"OracleDetector: {len(gt)} ground-truth frames for {len(sequence)} frames"
            )
        self._gt: list[FrameGT] | None = None if gt is None else list(gt)

    def reset(self) -> None:
        """Nothing to forget: detections depend only on (seed, frame index)."""

    def _frame_gt(self, index: int) -> FrameGT:
        if self._gt is None:
            from icmapper.data.gt import sequence_gt

            self._gt = list(sequence_gt(self.sequence, self.range))
        if not 0 <= index < len(self._gt):
            raise IndexError(f"OracleDetector: frame {index} out of range ({len(self._gt)} frames)")
        return self._gt[index]

    def detect(self, frame: Frame) -> Detections:
        """Noisy ground truth of frame.index: classes (k,), scores (k,), points (k, 20, 2) ego,
        gt_ids (k,) (-1 for false detections), queries None."""
        gt = self._frame_gt(frame.index)
        nz = self.noise
        g = np.random.default_rng([self.seed, frame.index])
        n = gt.points.shape[1] if len(gt) else NUM_INSTANCE_POINTS
        classes: list[int] = []
        points: list[NDArray[np.float64]] = []
        gt_ids: list[int] = []
        # Draw the same number of variates per instance whatever happens to it, so that changing one
        # rate does not reshuffle the noise of the other instances.
        for i in range(len(gt)):
            u_drop, u_part, a, f = g.random(4)
            offset = g.normal(0.0, 1.0, 2) * nz.offset_std  # (2,)
            jitter = g.normal(0.0, 1.0, (n, 2)) * nz.jitter_std  # (n, 2)
            if u_drop < nz.drop_rate:
                continue
            cls = int(gt.classes[i])
            pts = gt.points[i].astype(np.float64)  # (n, 2)
            if cls != MapClass.PED_CROSSING and u_part < nz.partial_rate:
                frac = nz.partial_min + f * (1.0 - nz.partial_min)
                start = a * (1.0 - frac)
                pts = _sub_range(pts, start, start + frac, n)
            classes.append(cls)
            points.append(pts + offset + jitter)
            gt_ids.append(int(gt.ids[i]))
        num_true = len(classes)
        for _ in range(int(g.poisson(nz.false_rate)) if nz.false_rate > 0 else 0):
            cls, pts = _false_instance(g, self.range, n)
            classes.append(cls)
            points.append(pts + g.normal(0.0, 1.0, (n, 2)) * nz.jitter_std)
            gt_ids.append(-1)
        k = len(classes)
        mean = np.array([nz.score_true] * num_true + [nz.score_false] * (k - num_true))  # (k,)
        scores = np.clip(mean + g.normal(0.0, 1.0, k) * nz.score_std, 0.0, 1.0)  # (k,)
        pts_arr = np.stack(points) if k else np.zeros((0, n, 2))  # (k, n, 2)
        if nz.pose_xy_std > 0 or nz.pose_yaw_std > 0:
            yaw = g.normal(0.0, nz.pose_yaw_std)
            rot = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
            pts_arr = pts_arr @ rot.T + g.normal(0.0, nz.pose_xy_std, 2)  # (k, n, 2)
        order = g.permutation(k)
        return Detections(
            classes=np.asarray(classes, np.int64)[order],
            scores=scores.astype(np.float32)[order],
            points=pts_arr.astype(np.float32)[order],
            queries=None,
            gt_ids=np.asarray(gt_ids, np.int64)[order],
        )

    def with_noise(self, noise: OracleNoise | str, seed: int | None = None) -> OracleDetector:
        """A copy with other noise (sharing the cached ground truth)."""
        other = OracleDetector(
            self.sequence, self.range, noise, self.seed if seed is None else seed
        )
        other._gt = self._gt
        return other


__all__ = ["OracleDetector", "OracleNoise"]
