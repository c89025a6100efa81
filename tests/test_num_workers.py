"""``data.num_workers = -1`` chooses the DataLoader workers from the cores (cores - 1, at most
``AUTO_WORKERS_MAX``); other negative values are refused."""

from __future__ import annotations

from pathlib import Path

import pytest
from icmapper.training.config import AUTO_WORKERS_MAX, load_config, resolve_num_workers

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize(
    ("cores", "expected"), [(1, 0), (2, 1), (4, 3), (9, 8), (16, AUTO_WORKERS_MAX), (128, 8)]
)
def test_auto_is_cores_less_one_at_most_the_cap(cores: int, expected: int) -> None:
    assert AUTO_WORKERS_MAX == 8
    assert resolve_num_workers(-1, cores=cores) == expected


def test_explicit_counts_are_kept() -> None:
    for n in (0, 1, 14, 32):
        assert resolve_num_workers(n, cores=2) == n


def test_auto_on_this_machine_is_in_range() -> None:
    assert 0 <= resolve_num_workers(-1) <= AUTO_WORKERS_MAX


def test_config_accepts_minus_one_and_refuses_less() -> None:
    cfg = load_config(REPO / "configs" / "small.toml", {"data.num_workers": -1})
    assert cfg.data.num_workers == -1
    with pytest.raises(ValueError, match="num_workers"):
        load_config(REPO / "configs" / "small.toml", {"data.num_workers": -2})
    with pytest.raises(ValueError, match="num_workers"):
        resolve_num_workers(-2, cores=4)
