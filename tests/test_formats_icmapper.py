"""icmapper's prediction file (formats/icmapper_json.py): round trips, matching frames to the
source, bad files, and a run mapped from a recorded file equals the run of the live detector."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from icmapper.data.sources import open_source
from icmapper.data.types import RANGE_60x30, Sequence
from icmapper.formats import PredictedFrame, PredictionFileError, PredictionSet, read_predictions
from icmapper.formats.export import detections_to_predictions, write_predictions
from icmapper.formats.source import PredictionInput
from icmapper.mapping.run import DetectionInput, map_sequence, method_factory

SPEC = "sim:val:1"


@pytest.fixture(scope="module")
def seq() -> Sequence:
    return open_source(SPEC, image_size=(32, 88), render=True)[0]


def _frame(rng: np.random.Generator, seq: Sequence, t: int, k: int, ids: bool) -> PredictedFrame:
    pts = rng.normal(0, 5, (k, 20, 2)).astype(np.float32)  # (k, 20, 2)
    return PredictedFrame(
        f"{seq.name}:{t}", float(seq.timestamps[t]), seq.name,
        rng.integers(0, 3, k).astype(np.int64), rng.random(k).astype(np.float32), pts,
        np.asarray(seq.poses[t]), np.arange(k, dtype=np.int64) * 3 if ids else None,
        rng.normal(0, 1, (k, 8)).astype(np.float32),
    )  # fmt: skip


def test_round_trip_is_bit_exact(tmp_path: Path, seq: Sequence) -> None:
    rng = np.random.default_rng(0)
    frames = [_frame(rng, seq, t, k, ids=t % 2 == 0) for t, k in enumerate((3, 0, 5))]
    preds = PredictionSet("icmapper", "", frames, "100x50", "ego", {"method": "m"})
    path = write_predictions(tmp_path / "p.json", preds, "icmapper")
    back = read_predictions(path)  # format recognised from the content
    assert back.format == "icmapper" and back.range_name == "100x50"
    assert back.meta["method"] == "m"
    for a, b in zip(frames, back.frames, strict=True):
        assert (a.token, a.timestamp, a.sequence) == (b.token, b.timestamp, b.sequence)
        np.testing.assert_array_equal(a.classes, b.classes)
        np.testing.assert_array_equal(a.scores, b.scores)
        np.testing.assert_array_equal(a.points, b.points)
        np.testing.assert_array_equal(a.pose, b.pose)
        if len(a):
            np.testing.assert_array_equal(a.queries, b.queries)
        assert (a.track_ids is None) == (b.track_ids is None) or len(a) == 0
        if a.track_ids is not None and len(a):
            np.testing.assert_array_equal(a.track_ids, b.track_ids)


def _write(path: Path, frames: list[dict], version: int = 1) -> Path:
    path.write_text(
        json.dumps({"format": "icmapper-predictions", "version": version, "frames": frames})
    )
    return path


def _inst(cls: str = "divider", pts: object = None) -> dict:
    return {"class": cls, "score": 0.5, "points": pts or [[0, 0], [5, 0], [10, 1]]}


@pytest.mark.parametrize(
    ("frames", "version", "message"),
    [
        ([{"token": "a", "instances": []}], 2, "unknown icmapper-predictions version 2"),
        ([{"token": "a", "instances": [_inst("lane")]}], 1, "unknown class name 'lane'"),
        ([{"token": "a", "instances": [_inst(pts=[[0, 0], [float("nan"), 1]])]}], 1, "NaN"),
        ([{"instances": []}], 1, "needs a 'token' or a 'timestamp'"),
        ([{"token": "a", "instances": [{**_inst(), "track_id": 1}, _inst()]}], 1, "not all"),
        (
            [{"token": "a", "instances": [{**_inst(), "track_id": 1}, {**_inst(), "track_id": 1}]}],
            1,
            "unique",
        ),
        ([{"token": "a", "instances": [_inst(pts=[[0, 0]])]}], 1, "at least 2"),
    ],
)
def test_bad_files_name_the_problem(
    tmp_path: Path, frames: list[dict], version: int, message: str
) -> None:
    path = _write(tmp_path / "bad.json", frames, version)
    with pytest.raises(PredictionFileError, match=message) as info:
        read_predictions(path)
    assert str(path) in str(info.value)


def test_not_json_and_missing_file(tmp_path: Path) -> None:
    with pytest.raises(PredictionFileError, match="not found"):
        read_predictions(tmp_path / "nope.json")
    (tmp_path / "x.json").write_text("{")
    with pytest.raises(PredictionFileError, match="not a readable JSON"):
        read_predictions(tmp_path / "x.json")


def test_points_are_resampled_unless_twenty(tmp_path: Path) -> None:
    twenty = np.cumsum(np.random.default_rng(1).random((20, 2)), axis=0).tolist()
    ring = [[0, 0], [4, 0], [4, 3], [0, 3], [0, 0]]
    path = _write(
        tmp_path / "p.json",
        [{"token": "a", "instances": [_inst(pts=twenty), _inst("ped_crossing", ring)]}],
    )
    f = read_predictions(path).frames[0]
    np.testing.assert_array_equal(f.points[0], np.asarray(twenty, np.float32))  # kept as given
    from shapely.geometry import Polygon  # oracle: every resampled point lies on the ring

    poly = Polygon(ring)
    assert f.points.shape == (2, 20, 2)
    assert max(poly.exterior.distance(__import__("shapely").Point(p)) for p in f.points[1]) < 1e-5
    assert not np.allclose(f.points[1][0], f.points[1][-1])  # the repeat is gone


def test_frames_are_matched_by_token_or_timestamp(tmp_path: Path, seq: Sequence) -> None:
    n = len(seq)
    frames = []
    for t in range(n):  # alternate: token only, timestamp only (with the sequence), both
        f: dict = {"instances": [_inst()]}
        if t % 3 != 1:
            f["token"] = f"{seq.name}:{t}"
        if t % 3 != 0:
            f["timestamp"] = float(seq.timestamps[t])
            f["sequence"] = seq.name
        frames.append(f)
    frames.reverse()  # file order does not matter
    inp = PredictionInput(read_predictions(_write(tmp_path / "p.json", frames)), SPEC, [seq])
    assert len(inp.frames(seq)) == n


def test_frame_mismatches_are_errors_naming_the_frame(tmp_path: Path, seq: Sequence) -> None:
    full = [{"token": f"{seq.name}:{t}", "instances": []} for t in range(len(seq))]
    cases = [
        (full[:3] + full[4:], f"no predictions for frame 3 .*{seq.name}"),
        (full + [{"token": f"{seq.name}:2", "instances": []}], "appears twice"),
        (full + [{"token": "nowhere", "instances": []}], "token 'nowhere': token names no frame"),
        (full[1:] + [{"timestamp": 1e6, "instances": []}], "timestamp 1000000.0"),
        (
            [{**full[0], "timestamp": float(seq.timestamps[1])}] + full[1:],
            "token and timestamp disagree",
        ),
        (
            [{**full[0], "pose": (np.eye(4) * 2).tolist()}] + full[1:],
            "pose differs from the source",
        ),
    ]
    for i, (frames, message) in enumerate(cases):
        preds = read_predictions(_write(tmp_path / f"p{i}.json", frames))
        with pytest.raises(PredictionFileError, match=message):
            inp = PredictionInput(preds, SPEC, [seq])
            inp.check_complete(seq)


def test_run_from_recorded_file_equals_live_detector(tmp_path: Path, tiny_checkpoint: Path) -> None:
    """The tiny network's detections (with query features) recorded to a file, then mapped from
    the file: IC-Mapper (learned association + fusion of the same checkpoint) and a baseline give
    the same per-frame results and global maps as the live detector."""
    full = open_source(SPEC, image_size=(32, 88), render=True)[0]
    seq = replace(full, timestamps=full.timestamps[:6], poses=full.poses[:6])  # 6 frames
    live_inp = DetectionInput.parse("learned", str(tiny_checkpoint))
    rng = live_inp.perception_range()
    live = {}
    mapper, rec = method_factory("icmapper", live_inp, rng)(seq, None)
    live["icmapper"] = map_sequence(mapper, seq, True)
    assert rec is not None and rec.records[0].queries is not None
    live["post-track"] = map_sequence(
        method_factory("post-track", live_inp, rng)(seq, rec.records)[0], seq, True
    )
    preds = detections_to_predictions(SPEC, [seq], {seq.name: rec.records}, rng.name)
    path = write_predictions(tmp_path / "dets.json", preds, "icmapper")

    file_inp = DetectionInput.parse(f"file:{path}:icmapper", str(tiny_checkpoint))
    assert file_inp.networks == str(tiny_checkpoint) and not file_inp.needs_images
    file_inp.match(SPEC, [seq])
    for name, (frames_live, map_live) in live.items():
        method, _ = method_factory(name, file_inp, rng)(seq, None)
        frames_file, map_file = map_sequence(method, seq, False)
        for a, b in zip(frames_live, frames_file, strict=True):
            np.testing.assert_array_equal(a.classes, b.classes)
            np.testing.assert_array_equal(a.scores, b.scores)
            np.testing.assert_array_equal(a.points, b.points)
            np.testing.assert_array_equal(a.track_ids, b.track_ids)
        assert sorted(map_live.ids().tolist()) == sorted(map_file.ids().tolist())
        for i in map_live.ids().tolist():
            ca, pa = map_live.get(i)
            cb, pb = map_file.get(i)
            assert ca == cb
            np.testing.assert_array_equal(pa, pb)


def test_file_without_queries_runs_every_oracle_method(tmp_path: Path, seq: Sequence) -> None:
    """No query features: IC-Mapper associates by position (like on the oracle): its run from a
    file of the oracle's detections equals its run on the oracle."""
    from icmapper.mapping.oracle import OracleDetector

    short = replace(seq, timestamps=seq.timestamps[:8], poses=seq.poses[:8])
    oracle = OracleDetector(short, rng=RANGE_60x30, noise="medium", seed=0)
    records = {t: oracle.detect(short.frame(t, with_images=False)) for t in range(len(short))}
    preds = detections_to_predictions(SPEC, [short], {short.name: records}, "60x30")
    path = write_predictions(tmp_path / "oracle.json", preds, "icmapper")
    file_inp = DetectionInput.parse(f"file:{path}", "no-such-checkpoint.pt")
    assert file_inp.networks is None  # no queries: no networks needed
    file_inp.match(SPEC, [short])
    oracle_inp = DetectionInput.parse("oracle:medium", None)
    for name in ("icmapper", "post-track", "vma", "cluster-fit", "polymerge"):
        a, _ = map_sequence(
            method_factory(name, oracle_inp, RANGE_60x30)(short, None)[0], short, False
        )
        b, _ = map_sequence(
            method_factory(name, file_inp, RANGE_60x30)(short, None)[0], short, False
        )
        for fa, fb in zip(a, b, strict=True):
            np.testing.assert_array_equal(fa.track_ids, fb.track_ids, err_msg=name)
            np.testing.assert_array_equal(fa.points, fb.points, err_msg=name)
