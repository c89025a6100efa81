"""Run folder format: round trip, and clear errors naming file and frame on bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from icmapper.eval.evaluate import check_run_frames
from icmapper.eval.runfmt import FramePredictions, RunFormatError, RunWriter, read_run


def _frames(rng: np.random.Generator, t: int) -> list[FramePredictions]:
    out = []
    for f in range(t):
        k = int(rng.integers(0, 5))
        pose = np.eye(4)
        pose[0, 3] = f
        out.append(
            FramePredictions(
                f, pose, rng.integers(0, 3, k), rng.random(k),
                rng.normal(size=(k, 20, 2)).astype(np.float32), np.arange(k), 0.5 * f,
            )
        )  # fmt: skip
    return out


def _write(tmp_path: Path, t: int = 4) -> tuple[Path, list[FramePredictions]]:
    frames = _frames(np.random.default_rng(0), t)
    with RunWriter(tmp_path / "run", "oracle", "sim:val:1", "60x30") as w:
        w.add_sequence("seq-a", frames)
    return tmp_path / "run", frames


def test_round_trip(tmp_path: Path) -> None:
    path, frames = _write(tmp_path)
    run = read_run(path)
    assert (run.method, run.source, run.range_name) == ("oracle", "sim:val:1", "60x30")
    rs = run.sequences[0]
    assert rs.name == "seq-a" and len(rs) == 4 and rs.global_map_path is None
    for t, fp in enumerate(frames):
        got = rs.frame(t)
        assert got.frame_index == fp.frame_index and got.timestamp == fp.timestamp
        np.testing.assert_array_equal(got.points, fp.points)
        np.testing.assert_array_equal(got.track_ids, fp.track_ids)
        np.testing.assert_array_equal(got.pose, fp.pose)


def test_incomplete_run_and_unknown_version(tmp_path: Path) -> None:
    path, _ = _write(tmp_path)
    meta = json.loads((path / "run.json").read_text())
    meta["version"] = 99
    (path / "run.json").write_text(json.dumps(meta))
    with pytest.raises(RunFormatError, match=r"run\.json.*unknown version 99"):
        read_run(path)
    (path / "run.json").unlink()
    with pytest.raises(RunFormatError, match="incomplete run"):
        read_run(path)


def test_missing_and_truncated_files(tmp_path: Path) -> None:
    path, _ = _write(tmp_path)
    data = (path / "seq-a.npz").read_bytes()
    (path / "seq-a.npz").write_bytes(data[: len(data) // 2])
    with pytest.raises(RunFormatError, match=r"seq-a\.npz: unreadable or truncated"):
        read_run(path)
    (path / "seq-a.npz").unlink()
    with pytest.raises(RunFormatError, match=r"seq-a\.npz: missing"):
        read_run(path)
    (path / "run.json").write_text('{"format": "icmapper-run", "vers')
    with pytest.raises(RunFormatError, match=r"run\.json: unreadable or truncated"):
        read_run(path)


def test_nan_points_name_file_and_frame(tmp_path: Path) -> None:
    path, _ = _write(tmp_path, t=6)
    with np.load(path / "seq-a.npz") as z:
        arrays = {k: z[k] for k in z.files}
    rows_before = int(arrays["counts"][:3].sum())
    assert arrays["counts"][3] > 0
    arrays["points"][rows_before, 4, 1] = np.nan  # first prediction of frame 3
    np.savez(path / "seq-a.npz", **arrays)
    with pytest.raises(RunFormatError, match=r"seq-a\.npz: frame 3: points contain NaN"):
        read_run(path)


def test_writer_rejects_bad_frames(tmp_path: Path) -> None:
    frames = _frames(np.random.default_rng(1), 3)
    bad = frames[1]
    bad.points = np.full((len(bad), 20, 2), np.nan, np.float32)
    w = RunWriter(tmp_path / "r", "m", "sim:val", "60x30")
    if len(bad):
        with pytest.raises(ValueError, match="'s' frame 1: points or scores contain NaN"):
            w.add_sequence("s", frames)
    dup = _frames(np.random.default_rng(2), 1)[0]
    dup.track_ids = np.zeros(len(dup), np.int64)
    if len(dup) > 1:
        with pytest.raises(ValueError, match="unique"):
            w.add_sequence("t", [dup])


class _Seq:
    def __init__(self, name: str, poses: np.ndarray) -> None:
        self.name, self.poses = name, poses

    def __len__(self) -> int:
        return len(self.poses)


def test_frames_must_match_the_source(tmp_path: Path) -> None:
    path, frames = _write(tmp_path)
    run = read_run(path)
    poses = np.stack([f.pose for f in frames])
    assert check_run_frames(run, [_Seq("seq-a", poses)])
    with pytest.raises(RunFormatError, match=r"seq-a\.npz: 4 frames, the source sequence has 5"):
        check_run_frames(run, [_Seq("seq-a", np.concatenate([poses, poses[:1]]))])
    moved = poses.copy()
    moved[2, 1, 3] += 1.0
    with pytest.raises(RunFormatError, match=r"seq-a\.npz: frame 2: pose differs"):
        check_run_frames(run, [_Seq("seq-a", moved)])
    with pytest.raises(RunFormatError, match="not in source"):
        check_run_frames(run, [_Seq("other", poses)])
