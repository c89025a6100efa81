"""The clean-map measures (``eval.fragmentation``) on hand-made maps whose answers are known, and
their place in ``evaluate``'s result and the report."""

from __future__ import annotations

import math

import numpy as np
import pytest
from icmapper.eval.fragmentation import fragmentation
from icmapper.eval.report import cleanliness_table


def line(x0: float, x1: float, y: float, n: int = 30) -> np.ndarray:
    return np.stack([np.linspace(x0, x1, n), np.full(n, y)], -1)


def rect(cx: float, cy: float, hx: float, hy: float) -> np.ndarray:
    corners = [[cx - hx, cy - hy], [cx + hx, cy - hy], [cx + hx, cy + hy], [cx - hx, cy + hy]]
    return np.array(corners)


#: A road: two dividers, one kerb, one crossing.
GT = [
    (1, line(0, 60, 0), False),
    (1, line(0, 60, 3.5), False),
    (2, line(0, 60, -5), False),
    (0, rect(70, 0, 2, 6), True),
]


def test_a_clean_map_scores_one_instance_per_element() -> None:
    pred = [(c, p + 0.2, closed, 3.0) for c, p, closed in GT]  # shifted 0.2 m, scores appended
    fr = fragmentation([pred], [GT])
    for name in ("ped_crossing", "divider", "boundary"):
        n = fr["count"][name]
        assert n["map"] == n["gt"] and n["ratio"] == 1.0
        assert fr["pieces"][name] == 1.0
        assert fr["split"][name] == 0.0 and fr["missed"][name] == 0.0
        assert fr["duplicates"][name] == 0.0 and fr["stray"][name] == 0.0


def test_pieces_duplicates_and_strays_are_counted() -> None:
    pred = [
        # the first divider in three pieces end to end, the second missed
        (1, line(0, 20, 0), False),
        (1, line(20, 40, 0.1), False),
        (1, line(40, 60, -0.1), False),
        # the kerb drawn twice, 0.4 m apart, and a 4 m stub across the lanes
        (2, line(0, 60, -5), False),
        (2, line(5, 55, -5.4), False),
        (2, np.array([[30.0, -4.0], [30.0, 0.0]]), False),
        # a small crossing inside the true one, and the true one
        (0, rect(70, 0, 2, 6), True),
        (0, rect(70, 1, 1, 2), True),
    ]
    fr = fragmentation([pred], [GT])
    assert fr["count"]["divider"] == {"map": 3, "gt": 2, "ratio": 1.5}
    assert fr["pieces"]["divider"] == 3.0  # the one covered divider is in 3 pieces
    assert fr["split"]["divider"] == 1.0 and fr["missed"]["divider"] == 0.5
    assert fr["duplicates"]["divider"] == 0.0
    # the kerb: 2 pieces (the copy beside it counts, the stub across covers less than
    # min_cover of it), one duplicate of 3
    assert fr["pieces"]["boundary"] == 2.0
    assert fr["duplicates"]["boundary"] == pytest.approx(1 / 3)
    assert fr["stray"]["boundary"] == pytest.approx(1 / 3)  # the stub across the lanes
    # the small crossing lies inside the big one: a duplicate (the smaller of the two)
    assert fr["duplicates"]["ped_crossing"] == 0.5
    assert fr["count"]["ped_crossing"]["ratio"] == 2.0


def test_a_line_that_turns_back_is_folded() -> None:
    # a divider drawn 0-60 m and back to 40 m 0.5 m beside itself (20 m on itself); the other
    # drawn straight with a 3 m hook at its end (turning within 4 m of arc: not a fold); the kerb
    # a U-turn around a 3 m wide island (its legs further apart than the gate)
    there_and_back = np.concatenate([line(0, 60, 0, 121), line(60, 40, 0.5, 41)[1:]])
    hook = np.concatenate([line(0, 60, 3.5, 121), [[60.0, 2.5], [59.5, 1.0]]])
    u_turn = np.concatenate([line(0, 30, -5, 61), line(30, 0, -8, 61)])
    pred = [(1, there_and_back, False), (1, hook, False), (2, u_turn, False), GT[3]]
    fr = fragmentation([pred], [GT])
    assert fr["folded"]["divider"] == 0.5
    assert fr["folded"]["boundary"] == 0.0
    assert math.isnan(fr["folded"]["ped_crossing"])  # crossings are rings: not measured
    # the folded line is one piece, no duplicate, not stray: only "folded" sees it
    assert fr["pieces"]["divider"] == 1.0 and fr["duplicates"]["divider"] == 0.0


def test_two_equal_copies_count_one_duplicate_and_sequences_pool() -> None:
    kerb = [(2, line(0, 60, -5), False)]
    fr = fragmentation([kerb + kerb, kerb], [kerb, kerb])
    assert fr["count"]["boundary"] == {"map": 3, "gt": 2, "ratio": 1.5}
    assert fr["duplicates"]["boundary"] == pytest.approx(1 / 3)  # one of the pair, not both
    # classes absent on both sides: nothing to average
    assert math.isnan(fr["pieces"]["divider"]) and math.isnan(fr["count"]["divider"]["ratio"])


def test_bad_arguments_are_refused() -> None:
    with pytest.raises(ValueError, match="2 predicted maps for 1"):
        fragmentation([[], []], [[]])
    with pytest.raises(ValueError, match="gate > 0"):
        fragmentation([[]], [[]], gate=float("nan"))


def test_the_report_has_a_cleanliness_row_per_method() -> None:
    fr = fragmentation([[(c, p, closed) for c, p, closed in GT]], [GT])
    table = cleanliness_table([{"method": "m", "range": "60x30", "mapping": {"fragmentation": fr}}])
    assert "| m | 60x30 | 1/1 (1.00) | 1.00 | 0.0 | 2/2 (1.00) |" in table
    empty = cleanliness_table([{"method": "m", "range": "60x30", "mapping": None}])
    assert "| m | 60x30 | - |" in empty
