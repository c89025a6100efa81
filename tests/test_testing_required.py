"""When a missing test tool skips and when it fails (icmapper.testing.required, devkits): a skip
only outside CI and only when the tool's distribution is absent (issue 34, points 2-3)."""

from __future__ import annotations

from pathlib import Path

import pytest
from icmapper.testing import devkits
from icmapper.testing.required import installed, missing, strict


@pytest.mark.parametrize(
    ("value", "want"), [("true", True), ("1", True), ("", False), ("0", False)]
)
def test_ci_variable(monkeypatch: pytest.MonkeyPatch, value: str, want: bool) -> None:
    monkeypatch.setenv("CI", value)
    assert strict() is want


def test_missing_skips_only_outside_ci_and_when_not_installed(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    assert installed("pytest") and not installed("no-such-distribution-icmapper")
    monkeypatch.delenv("CI", raising=False)
    with pytest.raises(pytest.skip.Exception, match="tool absent"):
        missing("tool absent", distribution="no-such-distribution-icmapper")
    with pytest.raises(pytest.fail.Exception, match="broken install"):
        missing("tool broken", distribution="pytest")
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match="CI=true requires it"):
        missing("tool absent", distribution="no-such-distribution-icmapper")


def test_a_devkit_whose_dependency_is_missing_fails(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """The devkits are installed ``--no-deps``: an installed devkit whose dependency is missing
    fails the test even outside CI, instead of turning the devkit comparisons into skips. Here a
    stand-in devkit package ``fakekit`` (its distribution: pytest, installed) imports a module
    that does not exist."""
    (tmp_path / "fakekit").mkdir()
    (tmp_path / "fakekit" / "__init__.py").write_text("import no_such_dependency_icmapper\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setitem(devkits.DISTRIBUTIONS, "fakekit", "pytest")
    monkeypatch.delenv("CI", raising=False)
    with pytest.raises(pytest.fail.Exception, match="'pytest' is installed"):
        devkits.require_devkit("fakekit")
    monkeypatch.delitem(devkits.DISTRIBUTIONS, "fakekit")  # not a known devkit: no distribution
    with pytest.raises(pytest.skip.Exception, match="no_such_dependency_icmapper"):
        devkits.require_devkit("fakekit")


def test_an_absent_devkit_skips_outside_ci(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("CI", raising=False)
    with pytest.raises(pytest.skip.Exception, match="no_such_devkit"):
        devkits.require_devkit("no_such_devkit.module")
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match="CI=true"):
        devkits.require_devkit("no_such_devkit.module")
