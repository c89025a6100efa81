"""Dense BEV segmentation targets (icmapper.models.segmentation) against shapely, and the loss."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
import torch
from icmapper.models.bev import bev_cell_centres
from icmapper.models.segmentation import rasterise, seg_loss
from shapely.geometry import LineString, Point, Polygon

GRID = (30, 15, 15.0, 7.5)  # bev_x, bev_y, half_x, half_y: 1 m cells


def _shapely_masks(points: np.ndarray, classes: np.ndarray, radius: float) -> np.ndarray:
    nx, ny, hx, hy = GRID
    centres = bev_cell_centres(nx, ny, hx, hy).numpy().reshape(-1, 2)
    out = np.zeros((3, nx * ny), dtype=np.float32)
    for pts, k in zip(points, classes, strict=True):
        if k == 0:
            poly = Polygon(pts)
            geom = shapely.union(poly, poly.exterior.buffer(radius))
            hit = [geom.covers(Point(c)) for c in centres]
        else:
            line = LineString(pts)
            hit = [line.distance(Point(c)) <= radius for c in centres]
        out[k] = np.maximum(out[k], np.asarray(hit, dtype=np.float32))
    return out.reshape(3, nx, ny)


def _random_instances(seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    pts, cls = [], []
    for _ in range(5):
        k = int(rng.integers(3))
        if k == 0:  # a rotated rectangle (crossing), contour of 20 points
            c, a = rng.uniform(-10, 10, 2), rng.uniform(0, np.pi)
            w, h = rng.uniform(2, 8), rng.uniform(1.5, 5)
            t = np.linspace(0, 4, 20, endpoint=False)
            u = np.interp(t, [0, 1, 2, 3, 4], [-w, w, w, -w, -w]) / 2
            v = np.interp(t, [0, 1, 2, 3, 4], [-h, -h, h, h, -h]) / 2
            r = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
            pts.append(np.stack([u, v], 1) @ r.T + c)
        else:  # a wavy open polyline
            x = np.linspace(rng.uniform(-20, -5), rng.uniform(5, 20), 20)
            y = rng.uniform(-6, 6) + 2 * np.sin(x / rng.uniform(3, 9))
            pts.append(np.stack([x, y], 1))
        cls.append(k)
    return np.asarray(pts), np.asarray(cls)


@pytest.mark.parametrize("seed", range(6))
def test_rasterise_matches_shapely(seed: int) -> None:
    points, classes = _random_instances(seed)
    radius = 0.75
    got = rasterise(torch.tensor(points), torch.tensor(classes), *GRID, line_radius=radius)
    want = _shapely_masks(points, classes, radius)
    assert got.shape == (3, GRID[0], GRID[1])
    assert want.sum() > 0
    # cells whose centre lies within 1e-4 m of the decision boundary may differ by round-off
    diff = (got.numpy() != want).sum()
    assert diff <= 2, f"{diff} cells differ from shapely"


def test_rasterise_empty_and_bad_input() -> None:
    out = rasterise(torch.zeros(0, 20, 2), torch.zeros(0, dtype=torch.int64), *GRID)
    assert out.shape == (3, 30, 15) and out.sum() == 0
    with pytest.raises(ValueError, match="points must be"):
        rasterise(torch.zeros(2, 20), torch.zeros(2, dtype=torch.int64), *GRID)
    with pytest.raises(ValueError, match="class 5"):
        rasterise(torch.zeros(1, 20, 2), torch.tensor([5]), *GRID)


def test_seg_loss_prefers_the_target() -> None:
    points, classes = _random_instances(1)
    target = rasterise(torch.tensor(points), torch.tensor(classes), *GRID)[None]  # (1, 3, X, Y)
    good = seg_loss((target * 2 - 1) * 8, target)
    bad = seg_loss((1 - target * 2) * 8, target)
    assert float(good) < 0.05 < 1.0 < float(bad)
