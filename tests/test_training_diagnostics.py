"""Learning curves (icmapper.training.curves) and the upper-bound diagnostics
(icmapper.training.diagnostics) on tiny runs."""

from __future__ import annotations

import csv
import json
import shutil
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import torch
from icmapper.data.types import CLASS_NAMES
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
    """Every snapshot gets a row of finite APs (mAP the mean of the classes'); the shipped
    checkpoint, placed as a third snapshot, gets the detection APs that `icmapper map` with the
    streaming detector and `icmapper eval` report for it (an untrained tiny run's APs are all 0,
    which would not tell a right number from a constant)."""
    from icmapper.checkpoints import DEFAULT_CHECKPOINT
    from icmapper.cli import main

    train(config_from_dict(TINY6), 1, tmp_path, progress=False)
    shutil.copyfile(DEFAULT_CHECKPOINT, tmp_path / "snapshots" / "stage1_step6.pt")
    assert curves.main([str(tmp_path), "--source", "sim:val:1"]) == 0
    with (tmp_path / "curves_stage1.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert [int(r["step"]) for r in rows] == [2, 4, 6]
    for r in rows:
        values = [float(r[k]) for k in curves.FIELDS[1:]]
        assert all(np.isfinite(v) and 0.0 <= v <= 100.0 for v in values), r
        assert values[-1] == pytest.approx(np.mean(values[:-1]), abs=0.01)  # 2 decimals written
    argv = ["map", "--source", "sim:val:1", "--checkpoint", str(DEFAULT_CHECKPOINT),
            "--method", "icmapper-base", "--out", str(tmp_path / "map")]  # fmt: skip
    argv.append("--no-progress")
    assert main(argv) == 0
    out = tmp_path / "eval.json"
    assert main(["eval", str(tmp_path / "map" / "icmapper-base"), "--json", str(out)]) == 0
    det = json.loads(out.read_text())["runs"][0]["detection"]
    shipped = rows[-1]
    assert float(shipped["mAP"]) == pytest.approx(100 * det["mAP"], abs=0.005)
    for name in CLASS_NAMES:
        assert float(shipped[f"AP_{name}"]) == pytest.approx(100 * det["AP_class"][name], abs=0.005)
    assert float(shipped["mAP"]) > 20.0  # the trained weights detect (65.07 when written)
    png = tmp_path / "curves_stage1.png"
    assert png.stat().st_size > 1000
    # a second call evaluates nothing new and keeps the rows
    before = (tmp_path / "curves_stage1.csv").read_text()
    assert curves.main([str(tmp_path), "--source", "sim:val:1"]) == 0
    assert (tmp_path / "curves_stage1.csv").read_text() == before


def test_curves_without_snapshots(tmp_path: Path) -> None:
    with pytest.raises(SystemExit, match="no snapshots"):
        curves.main([str(tmp_path)])


class _OracleHead(torch.nn.Module):
    """Stands in for the segmentation head when the "BEV" it gets is the rasterised truth
    (1, K, X, Y) in {0, 1}: logits of the truth itself, of nothing, or of every cell."""

    def __init__(self, predicts: str) -> None:
        super().__init__()
        self.predicts = predicts

    def forward(self, truth: torch.Tensor) -> torch.Tensor:
        if self.predicts == "truth":
            return 2 * truth - 1  # > 0 exactly on the truth's cells
        return torch.full_like(truth, -1.0 if self.predicts == "nothing" else 1.0)


def test_seg_iou_of_a_checkpoint(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """seg_iou (the checkpoint README's IoU figures) against known answers: with the head's
    input replaced by the rasterised truth of each frame, a head that returns the truth scores
    100 on every class, one that predicts nothing 0, and one that predicts every cell each
    class's share of the cells pooled over all frames (computed here from the truths)."""
    import icmapper.models.network as network
    import icmapper.training.bevcache as bevcache

    train(config_from_dict(TINY6), 1, tmp_path, progress=False)
    ckpt = tmp_path / "stage1.pt"
    iou = diagnostics.seg_iou(ckpt, "sim:val:1")  # the real network: any value, but a number
    assert set(iou) == set(CLASS_NAMES) and all(0.0 <= v <= 100.0 for v in iou.values())

    loaded = network.load_network(ckpt)
    cfg, rng = loaded.model, loaded.rng
    truths: list[torch.Tensor] = []  # (K, X, Y) bool per frame

    def truth_stream(det: object, item: dict) -> Iterator[torch.Tensor]:
        for g in item["gt"]:
            t = diagnostics.rasterise(g["points"], g["classes"], cfg.bev_x, cfg.bev_y,
                                      rng.half_x, rng.half_y, cfg.num_classes) > 0.5  # fmt: skip
            truths.append(t)
            yield t[None].float()  # (1, K, X, Y)

    monkeypatch.setattr(bevcache, "stream_bev", truth_stream)
    for predicts in ("truth", "nothing", "everything"):
        loaded.net.detector.seg = _OracleHead(predicts)
        monkeypatch.setattr(network, "load_network", lambda path, *a, **k: loaded)
        truths.clear()
        got = diagnostics.seg_iou(ckpt, "sim:val:1")
        pooled = torch.stack(truths).float()  # (frames, K, X, Y)
        share = 100 * pooled.mean(dim=(0, 2, 3))  # (K,) truth cells / all cells
        assert len(truths) > 10 and bool((share > 0).all())  # every class is on this drive
        want = {"truth": torch.full_like(share, 100.0), "nothing": torch.zeros_like(share),
                "everything": share}[predicts]  # fmt: skip
        for k, name in enumerate(CLASS_NAMES):
            assert got[name] == pytest.approx(float(want[k]), rel=1e-5, abs=1e-9), predicts

    monkeypatch.undo()
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
