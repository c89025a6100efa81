"""Hungarian matcher vs brute force over all permutations; point-order invariance."""

from __future__ import annotations

import itertools

import pytest
import torch
from icmapper.models.losses import best_order
from icmapper.models.matcher import HungarianMatcher, expand_point_orders, point_cost


def _brute_force(cost: torch.Tensor) -> float:
    q, g = cost.shape
    best = float("inf")
    if q >= g:
        for rows in itertools.permutations(range(q), g):
            best = min(best, sum(float(cost[r, c]) for c, r in enumerate(rows)))
    else:
        for cols in itertools.permutations(range(g), q):
            best = min(best, sum(float(cost[r, c]) for r, c in enumerate(cols)))
    return best


@pytest.mark.parametrize("q,g,seed", [(4, 3, 0), (5, 5, 1), (3, 5, 2), (6, 2, 3), (1, 1, 4)])
def test_matcher_matches_brute_force(q: int, g: int, seed: int) -> None:
    gen = torch.Generator().manual_seed(seed)
    logits = torch.randn(q, 3, generator=gen)
    points = torch.rand(q, 20, 2, generator=gen)
    classes = torch.randint(0, 3, (g,), generator=gen)
    gt = torch.rand(g, 20, 2, generator=gen)
    m = HungarianMatcher()
    pi, gi, order = m(logits, points, classes, gt)
    assert len(pi) == min(q, g) and len(set(pi.tolist())) == len(pi)
    cost, best = m.cost_matrix(logits, points, classes, gt)
    total = float(cost[pi, gi].sum())
    assert total == pytest.approx(_brute_force(cost), rel=1e-5, abs=1e-5)
    assert torch.equal(order, best[pi, gi])


def test_point_orders_counts_and_content() -> None:
    pts = torch.rand(3, 20, 2)
    orders, valid = expand_point_orders(pts, torch.tensor([0, 1, 2]))
    assert orders.shape == (3, 40, 20, 2)
    assert valid.sum(1).tolist() == [40, 2, 2]
    assert torch.equal(orders[1, 1], pts[1].flip(0))
    assert torch.equal(orders[0, 3], torch.roll(pts[0], -3, dims=0))
    assert torch.equal(orders[0, 20], pts[0].flip(0))


def test_cost_is_invariant_to_gt_order() -> None:
    gen = torch.Generator().manual_seed(5)
    pred = torch.rand(4, 20, 2, generator=gen)
    gt = torch.rand(2, 20, 2, generator=gen)
    cls = torch.tensor([0, 1])
    c0, _ = point_cost(pred, *expand_point_orders(gt, cls))
    moved = torch.stack([torch.roll(gt[0], 7, 0).flip(0), gt[1].flip(0)])
    c1, _ = point_cost(pred, *expand_point_orders(moved, cls))
    assert torch.allclose(c0, c1)
    # a reversed open polyline is a perfect match; a shifted crossing too
    tgt = best_order(gt.flip(1), gt, torch.tensor([1, 1]))
    assert torch.equal(tgt, gt.flip(1))
    ring = torch.roll(gt[:1], 5, 1)
    assert torch.equal(best_order(ring, gt[:1], torch.tensor([0])), ring)


def test_matcher_empty_gt_and_nan() -> None:
    m = HungarianMatcher()
    pi, gi, _ = m(
        torch.randn(3, 3),
        torch.rand(3, 20, 2),
        torch.zeros(0, dtype=torch.int64),
        torch.zeros(0, 20, 2),
    )
    assert pi.numel() == 0 and gi.numel() == 0
    bad = torch.rand(3, 20, 2)
    bad[0, 0, 0] = float("nan")
    with pytest.raises(ValueError, match="NaN"):
        m(torch.randn(3, 3), bad, torch.tensor([1]), torch.rand(1, 20, 2))


def _brute_force_capacity(cost: torch.Tensor, capacity: int) -> float:
    """Minimal total cost of assigning distinct predictions to GT instances, each instance taking
    up to ``capacity`` predictions and min(Q, capacity * G) pairs in all (enumerated directly on
    the (Q, G) cost, not on repeated columns)."""
    q, g = cost.shape
    pairs = min(q, capacity * g)
    best = float("inf")
    for labels in itertools.product(range(-1, g), repeat=q):  # -1: prediction unmatched
        used = [labels.count(c) for c in range(g)]
        if max(used) > capacity or sum(used) != pairs:
            continue
        best = min(best, sum(float(cost[r, c]) for r, c in enumerate(labels) if c >= 0))
    return best


@pytest.mark.parametrize("q,g,k,seed", [(5, 2, 2, 0), (6, 3, 2, 1), (4, 3, 3, 2), (7, 2, 3, 3)])
def test_one_to_many_matching_matches_brute_force(q: int, g: int, k: int, seed: int) -> None:
    """Hungarian matching against the GT repeated k times (losses.repeat_targets) is the optimal
    assignment in which every GT instance takes up to k predictions."""
    from icmapper.models.losses import repeat_targets

    gen = torch.Generator().manual_seed(seed)
    logits = torch.randn(q, 3, generator=gen)
    points = torch.rand(q, 20, 2, generator=gen)
    gt = {"classes": torch.randint(0, 3, (g,), generator=gen),
          "points01": torch.rand(g, 20, 2, generator=gen), "ids": torch.arange(g)}  # fmt: skip
    rep = repeat_targets(gt, k)
    assert rep["points01"].shape == (k * g, 20, 2) and torch.equal(rep["ids"] % g, rep["ids"])
    m = HungarianMatcher()
    pi, gi, _ = m(logits, points, rep["classes"], rep["points01"])
    counts = torch.bincount(rep["ids"][gi], minlength=g)
    assert int(counts.max()) <= k and len(set(pi.tolist())) == len(pi)
    cost, _ = m.cost_matrix(logits, points, gt["classes"], gt["points01"])  # (Q, G)
    total = float(cost[pi, rep["ids"][gi]].sum())
    assert total == pytest.approx(_brute_force_capacity(cost, k), rel=1e-5, abs=1e-5)
    with pytest.raises(ValueError, match="repeats"):
        repeat_targets(gt, 0)
