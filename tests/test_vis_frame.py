"""Per-frame pictures, the run replay behind them, videos and the `icmapper vis` command."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from icmapper.eval.runfmt import RunFormatError, RunWriter, read_run
from icmapper.vis.frame import camera_order, frame_picture, overview_bounds
from icmapper.vis.replay import load_map_items, open_replay
from icmapper.vis.style import CLASS_RGB
from PIL import Image

SOURCE = "sim:val:1"
SIZE = (64, 176)


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from icmapper.mapping.cli import run_methods

    out = tmp_path_factory.mktemp("run")
    (d,) = run_methods(
        ["icmapper"], SOURCE, out, "oracle:low", None, SIZE, progress=False, pictures=False
    )
    return d


def test_replay_pairs_the_run_with_its_source(run_dir: Path) -> None:
    replay = open_replay(run_dir, image_size=SIZE)
    rs = read_run(run_dir).sequences[0]
    items = load_map_items(rs.global_map_path)
    assert len(replay) == len(rs) and replay.name == rs.name
    t = len(rs) // 2
    view = replay.frame(t)
    np.testing.assert_array_equal(view.predictions.track_ids, rs.frame(t).track_ids)
    np.testing.assert_array_equal(view.pose, rs.poses[t])
    assert view.images is not None and view.images.shape == (6, 3, *SIZE)
    assert view.gt is not None and len(view.gt) > 0
    so_far = {m.id for m in items if m.first_frame <= int(rs.frame_index[t])}
    assert {m.id for m in view.map_so_far} == so_far
    assert 0 < len(so_far) < len(items)  # the map grows over the drive
    assert {m.id for m in replay.map_so_far(len(rs) - 1)} == {m.id for m in items}
    with pytest.raises(IndexError, match="out of range"):
        replay.frame(len(rs))


def test_replay_errors_name_the_problem(run_dir: Path, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="has no sequence 'nope'"):
        open_replay(run_dir, "nope", with_source=False)
    # A run whose poses are not the source's: refused (never draws the wrong drive's images).
    rs = read_run(run_dir).sequences[0]
    bad = tmp_path / "bad"
    frames = [rs.frame(t) for t in range(len(rs))]
    frames[3].pose = frames[3].pose.copy()
    frames[3].pose[0, 3] += 5.0
    with RunWriter(bad, "x", SOURCE, "60x30") as w:
        w.add_sequence(rs.name, frames)
    with pytest.raises(RunFormatError, match="frame 3: pose differs"):
        open_replay(bad)
    with RunWriter(tmp_path / "gone", "x", "av2:/no/such/log", "60x30") as w:
        w.add_sequence("a", frames[:1])
    with pytest.raises(ValueError, match="cannot open the run's source 'av2:/no/such/log'"):
        open_replay(tmp_path / "gone")


def test_frame_picture(run_dir: Path, tmp_path: Path) -> None:
    replay = open_replay(run_dir, image_size=SIZE)
    t = 10
    img = frame_picture(replay, t)
    arr = np.asarray(img)  # (H, W, 3)
    rows = camera_order(replay.source.rig.names)
    grid_w = 3 * SIZE[1] + 2 * 4
    assert arr.shape[0] > 2 * SIZE[0] and arr.shape[1] > grid_w + 200
    cams = arr[:, 4 : 4 + grid_w]
    # The frame's tracked predictions are drawn onto the cameras in their class colours.
    pred_classes = set(replay.frame(t).predictions.classes.tolist())
    for c in pred_classes:
        assert np.all(cams == CLASS_RGB[c], axis=-1).sum() > 20, c
    assert len(rows) == 2 and rows[0] == [2, 0, 1]  # FRONT_LEFT FRONT FRONT_RIGHT
    # Without the source: no cameras, still the BEV and the overview.
    bare = open_replay(run_dir, with_source=False)
    small = frame_picture(bare, t, overview_bounds(bare))
    assert bare.frame(t).images is None and bare.frame(t).gt is None
    assert small.height > 400 and small.width > 500  # BEV and overview at their default height


def _run_cli(*args: str) -> int:
    from icmapper.cli import main

    return main(list(args))


def test_vis_command_writes_pictures(run_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "pics"
    n = len(read_run(run_dir).sequences[0])
    assert _run_cli("vis", str(run_dir), "--frame", "0", "--frame", "5", "--out", str(out),
                    "--image-size", *map(str, SIZE)) == 0  # fmt: skip
    assert sorted(p.name for p in out.glob("*.png")) == ["frame_0000.png", "frame_0005.png"]
    with Image.open(out / "frame_0005.png") as im:
        assert im.mode == "RGB" and im.width > 800
    assert _run_cli("vis", str(run_dir), "--frame", str(n), "--out", str(out)) == 1


def test_video_mp4_and_gif_fallback(
    run_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from icmapper.vis import video

    frames = [f"--frame={k}" for k in range(4)]
    common = ["--image-size", *map(str, SIZE), "--out", str(tmp_path / "png")]
    if video.mp4_available():
        mp4 = tmp_path / "drive.mp4"
        assert _run_cli("vis", str(run_dir), *frames, *common, "--video", str(mp4)) == 0
        head = mp4.read_bytes()[:12]
        assert head[4:8] == b"ftyp"  # an MP4 container
        import imageio.v2 as imageio

        reader = imageio.get_reader(str(mp4), format="FFMPEG")
        n = sum(1 for _ in reader)
        reader.close()
        assert n == 4
    monkeypatch.setattr(video, "mp4_available", lambda: False)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert _run_cli("vis", str(run_dir), *frames, *common, "--video",
                        str(tmp_path / "drive2.mp4")) == 0  # fmt: skip
    assert any("writing a GIF instead" in str(w.message) for w in caught)
    gif = tmp_path / "drive2.gif"
    with Image.open(gif) as im:
        assert im.n_frames == 4
    with pytest.raises(ValueError, match="unknown video suffix"):
        video.write_video([], tmp_path / "x.webm")
    with pytest.raises(ValueError, match="no frames"):
        video.write_video([], tmp_path / "x.gif")
