"""Real-image sources end to end: two training steps of each real benchmark config
(configs/nuscenes_newsplit.toml, configs/av2_newsplit.toml) on the image fixtures, with the image
size and model width overridden by `--set` to fit the CPU, then `icmapper map` with the trained
checkpoint on real images and `icmapper eval` of the run."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from icmapper.cli import main
from icmapper.data.sources import open_source
from icmapper.testing.av2_fixture import write_av2_sensor_log
from icmapper.testing.nuscenes_fixture import write_nuscenes_fixture

CONFIGS = Path(__file__).resolve().parents[1] / "configs"
TINY = [
    "data.image_size=[32,64]",
    "data.clip_len=2",
    "data.num_workers=0",
    "model.backbone_widths=[8,16]",
    "model.backbone_depths=[1,1]",
    "model.channels=16",
    "model.bev_x=10",
    "model.bev_y=5",
    "model.num_queries=8",
    "model.num_layers=1",
    "model.heads=2",
    "model.topk=3",
    "model.fusion_layers=1",
    "stage1.batch_size=1",
    "stage1.steps=2",
    "stage1.warmup_steps=1",
    "amp=false",
    "ckpt_every=1000",
]


def _train_map_eval(config: str, source: str, val_source: str, out: Path) -> dict:
    sets = [*TINY, f'data.source="{source}"', 'data.split_file=""']
    args = ["train", "--config", str(CONFIGS / config), "--out", str(out / "train")]
    args += ["--max-steps", "2", "--no-progress"]
    for s in sets:
        args += ["--set", s]
    assert main(args) == 0
    ckpt = out / "train" / "stage1.pt"
    assert ckpt.is_file()
    assert (
        main(
            ["map", "--source", val_source, "--checkpoint", str(ckpt), "--out", str(out / "map")]
            + ["--no-progress", "--set", "detect_threshold=0.0", "--set", "track_threshold=0.0"]
            + ["--set", "min_hits=1"]
        )
        == 0
    )
    run = out / "map" / "icmapper"
    assert json.loads((run / "run.json").read_text())["source"] == val_source
    assert main(["eval", str(run), "--json", str(out / "eval.json")]) == 0
    return json.loads((out / "eval.json").read_text())


def _check_evaluation(result: dict, val_source: str) -> None:
    """The evaluation covers every frame of the validation source, with predictions (detection
    threshold 0) and ground truth, and every metric family is a number in its range."""
    frames = sum(len(s) for s in open_source(val_source, render=False))
    assert result["format"] == "icmapper-eval" and len(result["runs"]) == 1
    r = result["runs"][0]
    assert r["num_frames"] == frames > 0
    assert r["num_predictions"] > 0 and r["num_gt"] > 0
    assert 0.0 <= r["detection"]["mAP"] <= 1.0
    assert 0.0 <= r["consistency"]["C-mAP"] <= 1.0
    mota, ids = r["tracking"]["mean"]["MOTA"], r["tracking"]["mean"]["IDS"]
    assert np.isfinite(mota) and mota <= 1.0 and np.isfinite(ids) and ids >= 0.0
    # every detection is mapped (track threshold 0, min_hits 1): each class has map instances,
    # so its CD to the ground truth is a finite number (an empty class scores "inf" in the JSON)
    cds = r["mapping"]["CD"]
    assert all(isinstance(cd, float) and 0.0 <= cd < np.inf for cd in cds.values()), cds


@pytest.mark.slow
def test_nuscenes_config_trains_maps_and_evaluates(tmp_path: Path) -> None:
    root = write_nuscenes_fixture(tmp_path / "nusc", scene_lengths=(4, 3), images=True)
    (root / "splits.json").write_text(json.dumps({"train": ["scene-0001"], "val": ["scene-0002"]}))
    val = f"nuscenes:{root}:val"
    result = _train_map_eval("nuscenes_newsplit.toml", f"nuscenes:{root}:train", val, tmp_path)
    _check_evaluation(result, val)


@pytest.mark.slow
def test_av2_config_trains_maps_and_evaluates(tmp_path: Path) -> None:
    logs = tmp_path / "av2"
    log = write_av2_sensor_log(logs, duration_s=2.0)
    (logs / "splits.json").write_text(json.dumps({"train": [log.name], "val": [log.name]}))
    val = f"av2:{logs}:val"
    result = _train_map_eval("av2_newsplit.toml", f"av2:{logs}:train", val, tmp_path)
    _check_evaluation(result, val)
