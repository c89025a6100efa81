"""StreamMapNet / MapTracker submission files (formats/streammapnet.py): a file written the way
their ``format_results`` writes it, export round trips, numeric AV2 tokens, bad files, and the
`map` / `eval` / `export` commands on such files."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from icmapper.cli import main
from icmapper.data.sources import open_source
from icmapper.data.types import RANGE_60x30, Sequence
from icmapper.formats import PredictedFrame, PredictionFileError, read_predictions
from icmapper.formats.frames import SourceFrames
from icmapper.mapping.oracle import OracleDetector

SPEC = "sim:val:1"


@pytest.fixture(scope="module")
def seq() -> Sequence:
    return open_source(SPEC, render=False)[0]


def _submission(seq: Sequence, frames: range) -> tuple[dict, dict]:
    """A submission_vector.json as StreamMapNet/MapTracker write it, from oracle detections:
    crossings closed (first point repeated), MapTracker's extra keys; and the detections."""
    oracle = OracleDetector(seq, rng=RANGE_60x30, noise="medium", seed=0)
    results, dets = {}, {}
    for t in frames:
        d = oracle.detect(seq.frame(t, with_images=False))
        vecs = [
            np.concatenate([p, p[:1]]).tolist() if c == 0 else p.tolist()
            for c, p in zip(d.classes, d.points.astype(np.float64), strict=True)
        ]
        results[f"{seq.name}:{t}"] = {
            "vectors": vecs,
            "scores": d.scores.astype(float).tolist(),
            "labels": d.classes.tolist(),
            "props": [False] * len(d),
            "track_vectors": [],
            "track_scores": [],
            "track_labels": [],
        }
        dets[t] = d
    meta = {"use_lidar": False, "use_camera": True, "output_format": "vector"}
    return {"meta": meta, "results": results}, dets


def test_reads_their_file(tmp_path: Path, seq: Sequence) -> None:
    sub, dets = _submission(seq, range(len(seq)))
    path = tmp_path / "submission_vector.json"
    path.write_text(json.dumps(sub))
    preds = read_predictions(path)
    assert preds.format == "streammapnet" and preds.range_name == "60x30"
    by_token = {f.token: f for f in preds.frames}
    for t, d in dets.items():
        f = by_token[f"{seq.name}:{t}"]
        np.testing.assert_array_equal(f.classes, d.classes)
        np.testing.assert_array_equal(f.scores, d.scores)
        np.testing.assert_array_equal(f.points, d.points)  # the repeated first point dropped
        assert f.track_ids is None and f.queries is None and f.pose is None


def test_export_round_trip_and_commands(
    tmp_path: Path, seq: Sequence, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "runs"
    src = ["--source", SPEC, "--no-progress"]
    assert main(["map", *src, "--detections", "oracle:medium", "--method", "post-track",
                 "--out", str(out)]) == 0  # fmt: skip
    run = out / "post-track"
    sub = tmp_path / "sub.json"
    assert main(["export", str(run), "--format", "streammapnet", "--out", str(sub)]) == 0
    data = json.loads(sub.read_text())
    assert set(data) == {"meta", "results"} and len(data["results"]) == len(seq)
    first = data["results"][f"{seq.name}:0"]
    for v, lab in zip(first["vectors"], first["labels"], strict=True):
        assert len(v) == 20  # as theirs: 20 points per vector,
        assert lab != 0 or v[0] == v[-1]  # crossings closed by repeating the first point
    from icmapper.eval.runfmt import read_run

    stored = read_run(run).sequences[0]
    preds = {f.token: f for f in read_predictions(sub, "streammapnet").frames}
    for t in range(len(stored)):
        fp, f = stored.frame(t), preds[f"{seq.name}:{t}"]
        np.testing.assert_array_equal(fp.classes, f.classes)
        np.testing.assert_allclose(fp.scores, f.scores, rtol=1e-7)
        lines = fp.classes != 0
        np.testing.assert_array_equal(fp.points[lines], f.points[lines])  # exact
        # 20 distinct points -> 19 and the repeat: the one that shapes the ring least is left
        # out, the other 19 come back exactly (and one on the longest edge)
        for a, b in zip(fp.points[~lines], f.points[~lines], strict=True):
            kept = {tuple(p) for p in b.tolist()}
            assert sum(tuple(p) in kept for p in a.tolist()) == 19
    capsys.readouterr()
    assert main(["map", *src, "--detections", f"file:{sub}:streammapnet", "--method",
                 "icmapper", "--out", str(tmp_path / "from-file")]) == 0  # fmt: skip
    assert main(["eval", f"file:{sub}", "--source", SPEC, "--cmap", "both"]) == 0
    text = capsys.readouterr().out
    assert "C-mAP (MT)" in text and "streammapnet:sub.json" in text


def test_bad_submissions(tmp_path: Path, seq: Sequence, capsys: pytest.CaptureFixture) -> None:
    sub, _ = _submission(seq, range(len(seq)))
    tok = f"{seq.name}:0"
    cases = {
        "label": ({**sub["results"][tok], "labels": [7] + sub["results"][tok]["labels"][1:]},
                  "label 7 is not one of"),
        "lengths": ({**sub["results"][tok], "scores": []}, "vectors, 0 scores"),
        "nan": ({**sub["results"][tok], "vectors": [[[0, 0], [float("nan"), 0]]]
                 + sub["results"][tok]["vectors"][1:]}, "NaN"),
    }  # fmt: skip
    for name, (entry, message) in cases.items():
        path = tmp_path / f"{name}.json"
        path.write_text(json.dumps({**sub, "results": {**sub["results"], tok: entry}}))
        with pytest.raises(PredictionFileError, match=message):
            read_predictions(path)
    raster = tmp_path / "raster.json"
    raster.write_text(json.dumps({"meta": {"output_format": "raster"}, "results": {}}))
    with pytest.raises(PredictionFileError, match="only vector submissions"):
        read_predictions(raster)
    missing = tmp_path / "missing.json"
    missing.write_text(json.dumps(_submission(seq, range(1, len(seq)))[0]))
    capsys.readouterr()
    code = main(["map", "--source", SPEC, "--detections", f"file:{missing}", "--method",
                 "post-track", "--out", str(tmp_path / "o"), "--no-progress"])  # fmt: skip
    assert code == 1
    err = capsys.readouterr().err
    assert f"no predictions for frame 0 (token '{seq.name}:0'" in err and str(missing) in err


def test_av2_tokens_are_nanosecond_timestamps(seq: Sequence) -> None:
    """AV2 frames are named by their lidar timestamp in ns (StreamMapNet's / MapTracker's AV2
    token); seconds lose ~100 ns in float64, so digits are matched as timestamps."""
    ns = np.array([1_600_000_000_123_456_789 + 500_000_000 * k for k in range(4)])
    log = replace(seq, name="log-a", timestamps=ns * 1e-9, poses=seq.poses[:4])
    frames = SourceFrames.of("av2:/data/log-a", [log])
    empty = (np.zeros(0, np.int64), np.zeros(0, np.float32), np.zeros((0, 20, 2), np.float32))
    for k, v in enumerate(ns):
        f = PredictedFrame(str(int(v)), None, None, *empty)
        assert frames.locate(f, "test") == (0, k)
    with pytest.raises(PredictionFileError, match="names no frame"):
        frames.locate(PredictedFrame(str(int(ns[0]) + 10**7), None, None, *empty), "test")
