"""Full-state checkpoints of the online mapper (issue 6: "save mid-run and resume with an identical
result"): ``Mapper.save_state`` + ``Mapper.resume`` continue a run exactly like the uninterrupted
one, with the oracle source and with the learned networks (a tiny freshly initialised checkpoint);
a damaged sidecar is refused with a ValueError naming it and leaves the mapper as it was.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
from icmapper.data.sources import open_source
from icmapper.data.types import Sequence
from icmapper.mapping.config import MapperConfig
from icmapper.mapping.mapper import Mapper
from icmapper.mapping.state import STAT_COUNTS, STATE_VERSION, state_path
from icmapper.mapping.types import StepResult

REPO = Path(__file__).resolve().parents[1]


def snapshot(m: Mapper) -> dict[int, tuple[int, bytes]]:
    """The global map as {id: (class, point bytes)}."""
    out = {}
    for i in m.global_map.ids():
        cls, pts = m.global_map.get(int(i))
        out[int(i)] = (int(cls), np.asarray(pts).tobytes())
    return out


def assert_same_steps(a: list[StepResult], b: list[StepResult]) -> None:
    """Per-frame results are bit-identical (ids, points, detections, map updates)."""
    assert len(a) == len(b)
    for ra, rb in zip(a, b, strict=True):
        assert ra.frame_index == rb.frame_index
        np.testing.assert_array_equal(ra.track_ids, rb.track_ids)
        assert ra.points.tobytes() == rb.points.tobytes()
        assert ra.detections.scores.tobytes() == rb.detections.scores.tobytes()
        np.testing.assert_array_equal(ra.detections.classes, rb.detections.classes)
        assert ra.inserted == rb.inserted and ra.merged == rb.merged


def assert_same_state(a: Mapper, b: Mapper) -> None:
    """Same map (ids, classes, point bytes, info), tracker and counters."""
    assert snapshot(a) == snapshot(b)
    for i in a.global_map.ids():
        assert a.global_map.info(int(i)) == b.global_map.info(int(i))
    assert a.tracker.next_id == b.tracker.next_id
    ta, tb = a.tracker.tracks, b.tracker.tracks
    assert [(t.id, t.cls, t.age, t.hits) for t in ta] == [(t.id, t.cls, t.age, t.hits) for t in tb]
    assert all(x.points.tobytes() == y.points.tobytes() for x, y in zip(ta, tb, strict=True))
    assert a._alias == b._alias and a._untracked == b._untracked
    assert a.crossings.counts == b.crossings.counts
    assert a.merge_pose == b.merge_pose
    for n in STAT_COUNTS:
        assert getattr(a.stats, n) == getattr(b.stats, n), n


# ------------------------------------------------------------------------------------- oracle
@pytest.fixture(scope="module")
def sim_seq() -> Sequence:
    return open_source("sim:val:1", render=False)[0]


def test_oracle_resume_identical(tmp_path: Path, sim_seq: Sequence) -> None:
    seq = sim_seq
    n = len(seq)
    k = n // 2
    frames = [seq.frame(i, with_images=False) for i in range(n)]
    full = Mapper.with_oracle(seq, noise="low", seed=3)
    ref = []
    path = tmp_path / "mid.icmap"
    for i, f in enumerate(frames):
        ref.append(full.step(f))
        if i == k:
            full.save_state(path)
    assert path.is_file() and state_path(path).is_file()
    assert len(full.global_map) > 0

    resumed = Mapper.with_oracle(seq, noise="low", seed=3)
    resumed.resume(path)
    assert resumed.stats.frames == k + 1
    saved_counts = np.load(state_path(path))["crossing_counts"]  # (c, 2): id, complete views
    assert resumed.crossings.counts == {int(a): int(b) for a, b in saved_counts}
    got = [resumed.step(f) for f in frames[k + 1 :]]
    assert_same_steps(ref[k + 1 :], got)
    assert_same_state(full, resumed)
    # the crossing rule's view counts travelled (the drive has a crossing before the save)
    saved = np.load(state_path(path))["crossing_counts"]  # (c, 2)
    assert saved.shape[0] >= 1 and saved.shape[1] == 2
    # the run exercises the restored buffer: some track of the resumed part existed before
    saved_ids = {int(i) for r in ref[: k + 1] for i in r.track_ids}
    assert saved_ids & {int(i) for r in got for i in r.track_ids}

    # without the sidecar: the old map-only behaviour (empty buffer, new ids above the map)
    state_path(path).unlink()
    plain = Mapper.with_oracle(seq, noise="low", seed=3)
    plain.resume(path)
    assert len(plain.tracker) == 0
    assert plain.tracker.next_id == max(int(i) for i in plain.global_map.ids()) + 1


# ------------------------------------------------------------------------------------ learned
def test_learned_resume_identical(tmp_path: Path, tiny_checkpoint: Path) -> None:
    """The detector memory (BEV, propagated queries, last pose), the buffer with its query
    features and the map are restored: the continuation is bit-identical (CPU, one thread, the
    same inputs give the same floats, so exact equality is asserted)."""
    import torch

    torch.set_num_threads(1)
    seq = open_source("sim:val:1", image_size=(32, 88), render=True)[0]
    frames = [seq.frame(i) for i in range(6)]
    cfg = MapperConfig(detect_threshold=0.0, track_threshold=0.0, min_hits=1)
    full = Mapper.from_checkpoint(tiny_checkpoint, config=cfg)
    ref = []
    path = tmp_path / "learned.icmap"
    for i, f in enumerate(frames):
        ref.append(full.step(f))
        if i == 2:  # after frame 3 of 6
            full.save_state(path)
    assert len(full.global_map) > 0

    resumed = Mapper.from_checkpoint(tiny_checkpoint, config=cfg)
    resumed.resume(path)
    st = resumed.source._state  # type: ignore[attr-defined]
    assert st is not None and st.bev.shape[:2] == (1, 32)
    assert any(t.query is not None for t in resumed.tracker.tracks)
    got = [resumed.step(f) for f in frames[3:]]
    assert_same_steps(ref[3:], got)
    assert_same_state(full, resumed)
    for x, y in zip(full.tracker.tracks, resumed.tracker.tracks, strict=True):
        assert x.query is not None and y.query is not None
        assert x.query.tobytes() == y.query.tobytes()

    # a map-only resume loses the memory, so the same frames give other results (the state
    # is what makes the continuation identical, not the inputs alone)
    state_path(path).unlink()
    plain = Mapper.from_checkpoint(tiny_checkpoint, config=cfg)
    plain.resume(path)
    assert plain.source._state is None  # type: ignore[attr-defined]
    other = plain.step(frames[3])
    assert other.points.tobytes() != ref[3].points.tobytes()


# ------------------------------------------------------------------------------- bad sidecar
def test_corrupt_sidecar_refused(tmp_path: Path, sim_seq: Sequence) -> None:
    seq = sim_seq
    src = Mapper.with_oracle(seq, noise="low", seed=1)
    for i in range(4):
        src.step(seq.frame(i, with_images=False))
    path = tmp_path / "run.icmap"
    src.save_state(path)
    sidecar = state_path(path)
    good = sidecar.read_bytes()
    map_bytes = path.read_bytes()

    victim = Mapper.with_oracle(seq, noise="low", seed=1)
    for i in range(2):
        victim.step(seq.frame(i, with_images=False))
    before = snapshot(victim)
    tracks_before = [(t.id, t.points.tobytes()) for t in victim.tracker.tracks]

    def refused(data: bytes) -> None:
        sidecar.write_bytes(data)
        with pytest.raises(ValueError, match=str(sidecar.name)):
            victim.resume(path)
        assert snapshot(victim) == before
        assert [(t.id, t.points.tobytes()) for t in victim.tracker.tracks] == tracks_before
        assert victim.stats.frames == 2
        assert path.read_bytes() == map_bytes

    refused(good[: len(good) // 2])  # truncated
    refused(b"")  # empty
    refused(good[:100] + bytes(b ^ 0xFF for b in good[100:400]) + good[400:])  # flipped bytes

    # well-formed npz with wrong contents: a bad version, inconsistent counts, a foreign map
    with np.load(io.BytesIO(good), allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    for key, val in (
        ("version", np.array(99, np.int64)),
        ("version", np.array([2, 2], np.int64)),  # malformed: not a scalar
        ("version", np.array(2.0)),  # malformed: not an integer
        ("crossing_counts", np.array([[1, -1]], np.int64)),
        ("crossing_counts", arrays["crossing_counts"].reshape(-1)),
        ("track_counts", arrays["track_counts"] + 1),
        ("track_points", arrays["track_points"][:1]),
        ("map_sha256", np.array("0" * 64)),
        ("track_ids", arrays["track_ids"].astype(np.float64)),
        ("merge_pose", np.array([1.0, np.nan, 0.0])),
        ("merge_pose", np.array([1.0, 2.0])),
        ("merge_pose", np.array([1, 2, 3], np.int64)),
    ):
        bad = dict(arrays, **{key: val})
        with sidecar.open("wb") as fh:
            np.savez(fh, **bad)
        refused(sidecar.read_bytes())

    # a sidecar of the former format (before the crossing view counts) is named as such
    old = {k: v for k, v in arrays.items() if k != "crossing_counts"}
    with sidecar.open("wb") as fh:
        np.savez(fh, **dict(old, version=np.array(1, np.int64)))
    with pytest.raises(ValueError, match=f"format version 1, this build reads {STATE_VERSION}"):
        victim.resume(path)

    # the intact pair still resumes
    sidecar.write_bytes(good)
    victim.resume(path)
    assert snapshot(victim) == snapshot(src) and victim.stats.frames == 4
