"""When a test may skip for a missing tool, and when it must fail instead.

A test oracle or tool that the test extras or ``scripts/test.sh`` install (the official devkits,
Playwright and Chromium for the viewer) may be missing on a developer's machine: the test then
skips and says why. It must fail instead

- under ``CI=true``, where ``scripts/test.sh`` installed everything, so nothing may be missing;
- wherever the tool's distribution is installed but does not import (the devkits are installed
  ``--no-deps``: one missing dependency would otherwise silently turn every devkit check into a
  skip while the suite stays green).

Only an explicit opt-out variable (named by the caller) turns such a test into a skip under CI.
Imports pytest only when called.
"""

from __future__ import annotations

import importlib.metadata
import os
from typing import NoReturn

#: Values of ``CI`` that make missing test tools an error (GitHub Actions and most CI set "true").
_TRUE = {"1", "true", "yes"}


def strict() -> bool:
    """Whether missing test tools fail rather than skip: ``CI`` is set to true."""
    return os.environ.get("CI", "").strip().lower() in _TRUE


def installed(distribution: str) -> bool:
    """Whether the named distribution (pip name) is installed in this environment."""
    try:
        importlib.metadata.distribution(distribution)
    except importlib.metadata.PackageNotFoundError:
        return False
    return True


def missing(reason: str, *, distribution: str | None = None) -> NoReturn:
    """Ends the calling test for a missing tool: a failure when ``distribution`` is installed
    (then the tool is broken, not absent) or under ``CI=true``, a skip naming ``reason`` otherwise.
    """
    import pytest

    if distribution is not None and installed(distribution):
        pytest.fail(
            f"{reason}; the distribution {distribution!r} is installed, so this is a broken "
            "install (a missing dependency?), not an absent optional tool",
            pytrace=False,
        )
    if strict():
        pytest.fail(f"{reason}; CI=true requires it (scripts/test.sh installs it)", pytrace=False)
    pytest.skip(reason)
