"""Lines placed between the BEV cells: each vectorised line point moved across its line to the
maximum of its class's probabilities (``VectoriseParams.subcell``).

The skeleton of a mask runs through cell centres (1.2 m apart on the shipped grid, 0.3 m after the
vectoriser's upsampling), so a line drawn from it lies off the ridge of its probabilities by up to
a fraction of a cell. Each point of a line of the chosen classes looks along the line's normal,
``REACH`` metres to either side in ``SAMPLES`` steps, at the class's probabilities interpolated by
cubic B-splines (``scipy.ndimage``), takes the maximum there with a parabolic peak between the
samples, and moves by at most ``MAX_SHIFT``; the shifts are smoothed by a median of 3 along the
line. A point whose maximum lies at the end of its search (no peak inside) stays where it is.
No I/O.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from numpy.typing import NDArray

#: Metres searched on either side of a line point.
REACH = 0.9
#: Probability samples along the normal over [-REACH, REACH].
SAMPLES = 13
#: Metres a point moves at most.
MAX_SHIFT = 0.75


def subcell_lines(
    classes: NDArray[np.int64],
    points: NDArray[np.floating],
    prob: NDArray[np.floating],
    half_x: float,
    half_y: float,
    line_classes: Iterable[int],
) -> NDArray[np.float32]:
    """``points`` (N, P, 2) ego metres of instances of ``classes`` (N,) with every line of
    ``line_classes`` moved, point by point, across the line to the maximum of its class's
    probabilities ``prob`` (K, X, Y) over [-half_x, half_x] x [-half_y, half_y] -> (N, P, 2)
    float32 (the other instances unchanged)."""
    from scipy.ndimage import map_coordinates, spline_filter

    out = np.array(points, dtype=np.float32)  # (N, P, 2) a copy
    if out.ndim != 3 or out.shape[-1] != 2 or len(classes) != len(out):
        raise ValueError(f"subcell_lines: points must be (N, P, 2) for N classes, got {out.shape}")
    steps = np.linspace(-REACH, REACH, SAMPLES)  # (S,) metres along the normal
    k_x, k_y = prob.shape[1:]
    for c in sorted(set(int(k) for k in line_classes)):
        rows = np.flatnonzero(np.asarray(classes) == c)
        if len(rows) == 0 or c >= prob.shape[0]:
            continue
        field = spline_filter(np.asarray(prob[c], np.float64), order=3)  # (X, Y) coefficients
        p = out[rows].astype(np.float64)  # (M, P, 2)
        d = np.gradient(p, axis=1)  # (M, P, 2) along the line
        d /= np.maximum(np.linalg.norm(d, axis=2, keepdims=True), 1e-9)
        n = np.stack([-d[..., 1], d[..., 0]], axis=2)  # (M, P, 2) left normals
        q = p[:, :, None, :] + steps[None, None, :, None] * n[:, :, None, :]  # (M, P, S, 2)
        fi = (q[..., 0] + half_x) / (2 * half_x) * k_x - 0.5  # (M, P, S) cell index along x
        fj = (q[..., 1] + half_y) / (2 * half_y) * k_y - 0.5
        v = map_coordinates(field, [fi.ravel(), fj.ravel()], order=3, prefilter=False)
        v = v.reshape(fi.shape)  # (M, P, S) probabilities along the normals
        k = np.argmax(v, axis=2)[..., None]  # (M, P, 1)
        a = np.take_along_axis(v, np.maximum(k - 1, 0), axis=2)[..., 0]  # (M, P)
        b = np.take_along_axis(v, k, axis=2)[..., 0]
        e = np.take_along_axis(v, np.minimum(k + 1, SAMPLES - 1), axis=2)[..., 0]
        k = k[..., 0]
        curve = a - 2 * b + e
        inner = (k > 0) & (k < SAMPLES - 1) & (curve < 0)  # a peak inside the search
        frac = np.where(inner, 0.5 * (a - e) / np.where(inner, curve, -1.0), 0.0)
        shift = np.where(inner, steps[k] + frac * (steps[1] - steps[0]), 0.0)  # (M, P)
        s = np.pad(np.clip(shift, -MAX_SHIFT, MAX_SHIFT), ((0, 0), (1, 1)), mode="edge")
        shift = np.median(np.stack([s[:, :-2], s[:, 1:-1], s[:, 2:]]), axis=0)  # (M, P)
        out[rows] = (p + shift[..., None] * n).astype(np.float32)
    return out
