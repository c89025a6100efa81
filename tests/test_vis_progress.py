"""Progress output: a bar on a terminal, a few plain lines elsewhere (issue 17, point 4)."""

from __future__ import annotations

import io
import subprocess
import sys
from pathlib import Path

import pytest
from icmapper.progress import LineProgress, NoProgress, progress, progress_mode

REPO = Path(__file__).resolve().parents[1]


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def _drive(bar: object, n: int) -> None:
    for i in range(n):
        bar.update(1)  # type: ignore[attr-defined]
        bar.set_postfix_str(f"item {i}")  # type: ignore[attr-defined]
    bar.close()  # type: ignore[attr-defined]


def test_not_a_tty_gives_few_plain_lines(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("ICMAPPER_PROGRESS", raising=False)
    out = io.StringIO()
    bar = progress(1000, "mapping sim:val", unit="frame", stream=out)
    assert isinstance(bar, LineProgress)
    bar.min_interval = 0.0  # every tenth prints (the default also rate-limits by time)
    _drive(bar, 1000)
    text = out.getvalue()
    lines = text.splitlines()
    assert "\r" not in text
    assert len(lines) == 11, lines  # start, 9 intermediate tenths, done
    assert lines[0] == "mapping sim:val: started, 0/1000 frame"
    assert lines[1].startswith("mapping sim:val: 100/1000 frame (10%)")
    assert lines[-1].startswith("mapping sim:val: done, 1000/1000 frame in ")
    assert lines[-1].endswith("[item 999]")


class _Clock:
    """A clock the test moves: seconds = ``t``."""

    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def test_lines_are_rate_limited_by_time() -> None:
    """With an injected clock (no dependence on the machine's speed): one item per 10 ms, so a
    tenth of the work every second, and lines at most every 4.5 s: the tenths at 1 s and 6 s."""
    out, clock = io.StringIO(), _Clock()
    bar = LineProgress(1000, "x", stream=out, min_interval=4.5, clock=clock)
    for i in range(1000):
        clock.t = (i + 1) / 100
        bar.update(1)
    bar.close()
    lines = out.getvalue().splitlines()
    assert [ln.split(",")[0] for ln in lines] == [
        "x: started",
        "x: 100/1000 it (10%)",
        "x: 600/1000 it (60%)",
        "x: done",
    ]
    assert lines[1].endswith("1.0 s, 100.00 it/s") and lines[2].endswith("6.0 s, 100.00 it/s")
    assert lines[-1] == "x: done, 1000/1000 it in 10.0 s, 100.00 it/s"


def test_a_clock_that_stands_still_gives_one_intermediate_line() -> None:
    """All the work within one instant (a fast loop): only the first tenth is printed."""
    out = io.StringIO()
    _drive(LineProgress(10_000, "x", stream=out, clock=_Clock()), 10_000)
    lines = out.getvalue().splitlines()
    assert len(lines) == 3 and lines[1].startswith("x: 1000/10000 it (10%)"), lines


def test_a_tty_gets_a_tqdm_bar(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("ICMAPPER_PROGRESS", raising=False)
    out = _Tty()
    bar = progress(50, "stage 1", unit="step", stream=out)
    assert type(bar).__name__ == "tqdm"
    _drive(bar, 50)
    assert "\r" in out.getvalue() and "50/50" in out.getvalue()


def test_environment_override_and_disabled(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ICMAPPER_PROGRESS", "lines")
    assert progress_mode(_Tty()) == "lines"
    monkeypatch.setenv("ICMAPPER_PROGRESS", "bar")
    assert progress_mode(io.StringIO()) == "bar"
    monkeypatch.setenv("ICMAPPER_PROGRESS", "off")
    assert isinstance(progress(3, "x", stream=io.StringIO()), NoProgress)
    monkeypatch.setenv("ICMAPPER_PROGRESS", "sometimes")
    with pytest.raises(ValueError, match="ICMAPPER_PROGRESS"):
        progress_mode(io.StringIO())
    monkeypatch.delenv("ICMAPPER_PROGRESS")
    out = io.StringIO()
    _drive(progress(3, "x", enabled=False, stream=out), 3)
    assert out.getvalue() == ""


def test_map_command_logs_plain_lines_to_a_pipe(tmp_path: Path) -> None:
    """`icmapper map` with stderr piped (as in CI) prints a few lines, no carriage returns."""
    env = {"PYTHONPATH": str(REPO / "python"), "PATH": "/usr/bin:/bin", "OMP_NUM_THREADS": "1"}
    proc = subprocess.run(
        [sys.executable, "-m", "icmapper", "map", "--source", "sim:val:1",
         "--detections", "oracle:low", "--method", "post-track", "--out", str(tmp_path / "r")],
        capture_output=True, text=True, timeout=600, env=env, cwd=tmp_path,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "\r" not in proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.startswith("mapping sim:val:1")]
    assert 2 <= len(lines) <= 12, proc.stderr
    assert "started, 0/" in lines[0]
    assert "done" in lines[-1]
