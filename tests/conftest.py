"""Shared pytest fixtures.

`shared_data` locates the read-only real-data folder `../shared/data` next to the repository
(Argoverse 2 mini logs, split lists) and skips the test with the reason when it is absent.
"""

from __future__ import annotations

from pathlib import Path

import pytest

SHARED_DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Path to `../shared/data` (resolved); skips when the folder is not there."""
    path = SHARED_DATA.resolve()
    if not path.is_dir():
        pytest.skip(f"shared real data not available: {path} does not exist")
    return path
