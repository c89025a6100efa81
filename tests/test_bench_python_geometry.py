"""The Python-geometry benchmark program (benchmarks/bench_python_geometry.py) runs end to end on
a tiny workload and prints one ratio per choice (no timing is asserted)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

PROGRAM = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_python_geometry.py"


def test_python_geometry_bench_runs(capsys: pytest.CaptureFixture[str]) -> None:
    spec = importlib.util.spec_from_file_location("bench_python_geometry", PROGRAM)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    rc = module.main(["--rows", "60", "--pairs", "20", "--clouds", "50", "1100", "--repeat", "1"])
    out = capsys.readouterr().out
    assert rc == 0
    assert out.count("x faster") == 5  # resample, chamfer pairs, matrix, two cloud sizes
    diffs = [float(line.split("difference")[1].split()[0].strip("()m")) for line in out.splitlines()
             if "difference" in line]  # fmt: skip
    assert len(diffs) == 5 and max(diffs) < 1e-9  # the compared forms agree
