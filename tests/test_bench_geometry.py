"""The geometry benchmark program runs end to end on a tiny workload (no timing is asserted):
both engine paths and the shapely/scipy reference, and merge_many agrees with merge."""

from __future__ import annotations

import pytest
from icmapper import bench


def test_geometry_bench_runs(capsys: pytest.CaptureFixture[str]) -> None:
    rc = bench.main(["--sizes", "100", "--frames", "4", "--ref-frames", "4", "--rounds", "1"])
    out = capsys.readouterr().out
    assert rc == 0
    row = next(line for line in out.splitlines() if line.split() and line.split()[0] == "100")
    assert row.count("x") >= 3  # three ratios: merge, merge_many, sample
    assert row.split()[-1] == "4/4"  # the same instance ids on the first frames
    assert "with merge_many" in out


def test_city_instances_is_seeded() -> None:
    a = bench.city_instances(200, seed=3)
    b = bench.city_instances(200, seed=3)
    assert len(a) == 200
    assert all(ca == cb and (pa == pb).all() for (ca, pa), (cb, pb) in zip(a, b, strict=True))
