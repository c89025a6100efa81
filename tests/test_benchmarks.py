"""The benchmark programs (`python -m benchmarks NAME`): the geometry benchmark runs end to end on
a tiny workload (no timing is asserted: both engine paths and the shapely/scipy reference, and
merge_many agrees with merge); the runner dispatches to every benchmark; `icmapper bench` is gone
with an error that says where the benchmarks are."""

from __future__ import annotations

from pathlib import Path

import numpy as np
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
    for name in ("geometry", "render", "eval", "networks", "mapper", "viewer"):
        assert name in out
    with pytest.raises(SystemExit):
        runner.main(["no-such-benchmark"])
    assert "invalid choice" in capsys.readouterr().err


def test_city_instances_is_seeded() -> None:
    a = bench.city_instances(200, seed=3)
    b = bench.city_instances(200, seed=3)
    assert len(a) == 200
    assert all(ca == cb and (pa == pb).all() for (ca, pa), (cb, pb) in zip(a, b, strict=True))


def test_reference_merges_as_the_engine_does() -> None:
    """Like with like: after the same detections the shapely/scipy reference's polylines lie on
    the engine's (local refit, splice; a whole-instance refit would move their far parts too)
    and its crossings cover the same area."""
    import shapely

    instances = bench.city_instances(300, seed=5)
    poses = bench.random_poses(instances, 12, seed=6)
    gm = bench._engine_map(instances)
    rng = np.random.default_rng(7)
    dets = [bench.detections_for(gm, pose, rng) for pose in poses]
    ref = bench.ShapelyMap({int(i): gm.get(int(i)) for i in gm.ids()})
    for det in dets:
        for i, d in det:
            gm.merge(i, d, frame=1)
            ref.merge(i, d)
    lines, crossings = [], []
    for i in sorted({i for det in dets for i, _ in det}):
        cls, pts = gm.get(i)
        theirs = ref.geom[ref.slot[i]]
        if cls == bench.CLASS_CROSSING:
            ours = shapely.Polygon(pts)
            crossings.append(ours.intersection(theirs).area / ours.union(theirs).area)
        else:
            lines.append(shapely.hausdorff_distance(shapely.LineString(pts), theirs))
    assert len(lines) > 40 and len(crossings) > 10
    # polylines: the same curve (scipy's splprep is the engine's fit's oracle) to 1 mm
    assert max(lines) < 1e-3, max(lines)
    # crossings: the same union, resampled from another start point (corners cut differently)
    assert min(crossings) > 0.95, min(crossings)


def test_longrun_memory_trend_is_a_least_squares_slope() -> None:
    """The long run's memory verdict: a slope over all the second half's samples (a rise then a
    drop back at the last sample is a trend the two end points would hide)."""
    from benchmarks.longrun import rss_slope

    frames = [5001, 5501, 6001, 6501, 7001]
    slope, err = rss_slope(frames, [100.0 + 0.002 * (f - 5001) for f in frames])
    assert slope == pytest.approx(0.002) and err == pytest.approx(0.0, abs=1e-12)
    rss = [136.9, 140.0, 142.9, 147.7, 135.9]  # the two ends agree within 1 MB, the middle rises
    slope, err = rss_slope(frames, rss)
    assert slope == pytest.approx(np.polyfit(frames, rss, 1)[0]) and err > 0


@pytest.mark.parametrize(
    "name", ["geometry", "render", "eval", "networks", "mapper", "viewer", "vectorise"]
)
def test_every_benchmark_module_has_main(name: str) -> None:
    import importlib

    module = importlib.import_module(runner.BENCHMARKS[name][0])
    assert callable(module.main)


def test_icmapper_bench_says_where_the_benchmarks_are(capsys: pytest.CaptureFixture[str]) -> None:
    from icmapper.cli import main

    assert main(["bench", "geometry"]) == 2
    err = capsys.readouterr().err
    assert "python -m benchmarks geometry" in err and "not part of the installed package" in err


def test_vectorise_bench_runs_and_checks_agreement(capsys: pytest.CaptureFixture[str]) -> None:
    """The vectoriser benchmark on a tiny workload: both mask sets, the engine checked against
    the reference on every frame, the ratios printed (never asserted)."""
    from benchmarks import vectorise as bench_vec

    args = ["--frames", "3", "--gt-frames", "2", "--rounds", "1", "--thread-reps", "1"]
    assert bench_vec.main(args) == 0
    out = capsys.readouterr().out
    assert "engine = reference on 3/3" in out and "engine = reference on 2/2" in out
    assert out.count("two threads at once") == 2 and "x  (total time" in out


def test_mapper_bench_times_either_vectoriser() -> None:
    """The mapper benchmark's wrapper of the detector's ``vectorise`` returns what it wraps, the
    engine's or (``--vectoriser reference``) the former Python one: the same instances."""
    import icmapper.models.detector as detector

    from benchmarks import mapper as bench_mapper
    from benchmarks.vectorise import recorded_masks

    prob = recorded_masks(1)[0][0]  # (3, 50, 25)
    original = detector.vectorise
    try:
        got = []
        for reference in (False, True):
            spent = bench_mapper._time_vectoriser(reference=reference)
            got.append(detector.vectorise(prob, 30.0, 15.0))
            assert spent[0] > 0
            detector.vectorise = original
        np.testing.assert_array_equal(got[0].classes, got[1].classes)
        np.testing.assert_array_equal(got[0].points, got[1].points)
    finally:
        detector.vectorise = original


def test_pipeline_bench_runs_one_frame(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The paper-scale pipeline benchmark runs one frame on the CPU and prints every stage, and
    leaves no fresh checkpoint behind (about 100 MB each; temporary files go to ``tmp_path``)."""
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    assert runner.main(["pipeline", "--frames", "1"]) == 0
    assert not list(tmp_path.iterdir())
    out = capsys.readouterr().out
    assert "rasterised ground truth" in out
    for stage in ("detector", "vectorise", "association", "tracking", "fusion", "merge"):
        assert any(line.split()[:1] == [stage] for line in out.splitlines()), stage
    assert "frames/s" in out


def test_images_bench_worker_counts() -> None:
    """``python -m benchmarks images --workers``: integers as given, ``auto`` as
    ``data.num_workers = -1`` resolves on this machine, anything else refused."""
    from icmapper.training.config import resolve_num_workers

    from benchmarks import images

    auto = resolve_num_workers(-1)
    got = images.worker_counts(["0", "8", "auto"])
    assert got == [("0", 0), ("8", 8), (f"auto ({auto})", auto)]
    with pytest.raises(SystemExit, match="got '-1'"):
        images.worker_counts(["-1"])
