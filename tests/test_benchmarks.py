"""The benchmark programs (`python -m benchmarks NAME`): the geometry benchmark runs end to end on
a tiny workload (no timing is asserted: both engine paths and the shapely/scipy reference, and
merge_many agrees with merge); the runner dispatches to every benchmark; `icmapper bench` is gone
with an error that says where the benchmarks are."""

from __future__ import annotations

import pytest

from benchmarks import __main__ as runner
from benchmarks import geometry as bench

TINY = ["--sizes", "100", "--frames", "4", "--ref-frames", "4", "--rounds", "1"]


def _check_output(out: str) -> None:
    row = next(line for line in out.splitlines() if line.split() and line.split()[0] == "100")
    assert row.count("x") >= 3  # three ratios: merge, merge_many, sample
    assert row.split()[-1] == "4/4"  # the same instance ids on the first frames
    assert "with merge_many" in out


def test_geometry_bench_runs(capsys: pytest.CaptureFixture[str]) -> None:
    rc = bench.main(TINY)
    out = capsys.readouterr().out
    assert rc == 0
    _check_output(out)


def test_runner_dispatches_with_options(capsys: pytest.CaptureFixture[str]) -> None:
    assert runner.main(["geometry", *TINY]) == 0
    _check_output(capsys.readouterr().out)


def test_runner_lists_every_benchmark(capsys: pytest.CaptureFixture[str]) -> None:
    assert runner.main([]) == 2
    out = capsys.readouterr().out
    for name in ("geometry", "render", "eval", "networks", "mapper"):
        assert name in out
    with pytest.raises(SystemExit):
        runner.main(["no-such-benchmark"])
    assert "invalid choice" in capsys.readouterr().err


def test_city_instances_is_seeded() -> None:
    a = bench.city_instances(200, seed=3)
    b = bench.city_instances(200, seed=3)
    assert len(a) == 200
    assert all(ca == cb and (pa == pb).all() for (ca, pa), (cb, pb) in zip(a, b, strict=True))


@pytest.mark.parametrize("name", ["geometry", "render", "eval", "networks", "mapper"])
def test_every_benchmark_module_has_main(name: str) -> None:
    import importlib

    module = importlib.import_module(runner.BENCHMARKS[name][0])
    assert callable(module.main)


def test_icmapper_bench_says_where_the_benchmarks_are(capsys: pytest.CaptureFixture[str]) -> None:
    from icmapper.cli import main

    assert main(["bench", "geometry"]) == 2
    err = capsys.readouterr().err
    assert "python -m benchmarks geometry" in err and "not part of the installed package" in err
