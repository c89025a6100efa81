"""The Python-geometry benchmark program (`python -m benchmarks python-geometry`) runs end to end
on a tiny workload and prints one ratio per choice (no timing is asserted)."""

from __future__ import annotations

import pytest

from benchmarks import python_geometry


def test_python_geometry_bench_runs(capsys: pytest.CaptureFixture[str]) -> None:
    rc = python_geometry.main(
        ["--rows", "60", "--pairs", "20", "--clouds", "50", "1100", "--repeat", "1"]
    )
    out = capsys.readouterr().out
    assert rc == 0
    assert out.count("x faster") == 5  # resample, chamfer pairs, matrix, two cloud sizes
    diffs = [float(line.split("difference")[1].split()[0].strip("()m")) for line in out.splitlines()
             if "difference" in line]  # fmt: skip
    assert len(diffs) == 5 and max(diffs) < 1e-9  # the compared forms agree
