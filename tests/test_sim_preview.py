"""Preview picture and the `icmapper scenes preview` command (synthetic source)."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest
from icmapper.cli import main
from icmapper.data.preview import preview_png
from icmapper.data.sim import sim_sequence


def test_preview_png(tmp_path: Path) -> None:
    seq = sim_sequence(10_020, 1, image_size=(64, 176))
    with warnings.catch_warnings():
        warnings.simplefilter(
            "ignore"
        )  # gt.frame_gt may still fall back while the engine is incomplete
        out = preview_png(seq, 3, tmp_path / "sub" / "p.png")
    data = out.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000
    with pytest.raises(IndexError):
        preview_png(seq, 10_000, tmp_path / "q.png")


def test_cli_preview(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "cli.png"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rc = main(
            [
                "scenes",
                "preview",
                "--city",
                "10004",
                "--frame",
                "2",
                "--image-size",
                "64",
                "176",
                "--out",
                str(out),
            ]
        )
    assert rc == 0 and out.is_file()
    assert "wrote" in capsys.readouterr().out
    # a spec without a path, an unknown kind, a sequence out of range: clear errors (rc 1)
    assert main(["scenes", "preview", "--source", "av2", "--out", str(tmp_path / "x.png")]) == 1
    assert main(["scenes", "preview", "--source", "foo:1", "--out", str(tmp_path / "x.png")]) == 1
    bad = ["--source", "sim:val:1", "--sequence", "3", "--image-size", "32", "88"]
    assert main(["scenes", "preview", *bad, "--out", str(tmp_path / "x.png")]) == 1
    err = capsys.readouterr().err
    assert "unknown kind 'foo'" in err and "has 1 sequence(s)" in err
