"""Learning curves (icmapper.training.curves) and the upper-bound diagnostics
(icmapper.training.diagnostics) on tiny runs."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
import torch
from icmapper.testing.configs import tiny_raw
from icmapper.training import curves, diagnostics
from icmapper.training.config import config_from_dict
from icmapper.training.loop import train

TINY6 = tiny_raw(
    snapshot_every=2,
    model={"num_cameras": 6, "channels": 16, "num_layers": 1, "seg_head": True},
    stage1={"seg_weight": 1.0, "lr": 5e-4},
)


@pytest.fixture(autouse=True)
def _threads() -> None:
    torch.set_num_threads(1)


def test_curves_of_a_run(tmp_path: Path) -> None:
    train(config_from_dict(TINY6), 1, tmp_path, progress=False)
    assert curves.main([str(tmp_path), "--source", "sim:val:1"]) == 0
    with (tmp_path / "curves_stage1.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert [int(r["step"]) for r in rows] == [2, 4]
    for r in rows:
        values = [float(r[k]) for k in curves.FIELDS[1:]]
        assert all(0.0 <= v <= 100.0 for v in values if np.isfinite(v))
    png = tmp_path / "curves_stage1.png"
    assert png.stat().st_size > 1000
    # a second call evaluates nothing new and keeps the rows
    before = (tmp_path / "curves_stage1.csv").read_text()
    assert curves.main([str(tmp_path), "--source", "sim:val:1"]) == 0
    assert (tmp_path / "curves_stage1.csv").read_text() == before


def test_curves_without_snapshots(tmp_path: Path) -> None:
    with pytest.raises(SystemExit, match="no snapshots"):
        curves.main([str(tmp_path)])


def test_seg_iou_of_a_checkpoint(tmp_path: Path) -> None:
    train(config_from_dict(TINY6), 1, tmp_path, progress=False)
    iou = diagnostics.seg_iou(tmp_path / "stage1.pt", "sim:val:1")
    assert set(iou) == {"ped_crossing", "divider", "boundary"}
    assert all(0.0 <= v <= 100.0 for v in iou.values())
    raw = {**TINY6, "model": {**TINY6["model"], "seg_head": False}, "stage1": {"steps": 1}}
    train(config_from_dict(raw), 1, tmp_path / "noseg", progress=False)
    with pytest.raises(ValueError, match="no segmentation head"):
        diagnostics.seg_iou(tmp_path / "noseg" / "stage1.pt", "sim:val:1")


def test_perfect_bev_decoder_learns(tmp_path: Path) -> None:
    """Trained on the validation drive's own rasterised ground truth, the decoder's detections
    beat its untrained start: the diagnostic measures learning, not a constant."""
    cfg = tmp_path / "c.toml"
    cfg.write_text(
        "[model]\nchannels = 32\nnum_queries = 20\nnum_layers = 2\n"
        "[stage1]\nlr = 2e-3\nwarmup_steps = 0\n"
    )
    untrained = diagnostics.perfect_bev(cfg, 0, "sim:val:1", "sim:val:1", 4, log=False)
    trained = diagnostics.perfect_bev(cfg, 150, "sim:val:1", "sim:val:1", 4, log=False)
    assert trained["mAP"] > untrained["mAP"] + 0.02


def test_train_fill_cache_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from icmapper.cli import main

    repo = Path(__file__).resolve().parents[1]
    base = ["train", "--config", str(repo / "configs" / "small.toml"),
            "--set", 'data.source="sim:val:1"', "--set", "data.image_size=[32,64]"]  # fmt: skip
    cache = tmp_path / "cache"
    assert main([*base, "--set", f'data.cache_dir="{cache}"', "--fill-cache", "0/1"]) == 0
    frames = list(cache.rglob("*.npy"))
    assert len(frames) > 10 and np.load(frames[0]).shape == (6, 3, 32, 64)
    assert main([*base, "--set", f'data.cache_dir="{cache}"', "--fill-cache", "x"]) != 0
    assert "--fill-cache must be I/N" in capsys.readouterr().err
    assert main([*base, "--set", 'data.cache_dir=""', "--fill-cache", "0/1"]) != 0
    assert "needs data.cache_dir" in capsys.readouterr().err


def test_fusion_gain_of_the_shipped_checkpoint() -> None:
    """fusion-gain compares each fused detection with the truth before and after fusion; without
    fusion (the no-fusion mapper, every tracked detection counted) both numbers are the same."""
    from icmapper.checkpoints import DEFAULT_CHECKPOINT

    full = diagnostics.fusion_gain(Path(DEFAULT_CHECKPOINT), "sim:val:1")
    assert set(full) == {"ped_crossing", "divider", "boundary"}
    assert sum(v["n"] for v in full.values()) > 20
    for v in full.values():
        if v["n"]:
            assert 0.0 <= v["raw"] <= 1.5 and v["fused"] >= 0.0
    assert any(v["n"] and v["fused"] != v["raw"] for v in full.values())
    plain = diagnostics.fusion_gain(Path(DEFAULT_CHECKPOINT), "sim:val:1", variant="no-fusion")
    assert sum(v["n"] for v in plain.values()) > 20
    assert all(v["fused"] == v["raw"] for v in plain.values() if v["n"])
