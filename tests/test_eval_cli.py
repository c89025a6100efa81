"""`icmapper eval` end to end on runs made from ground truth with noise (synthetic source)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from icmapper.eval.runfmt import FramePredictions, RunWriter


def _noisy_run(path: Path, method: str, sigma: float, seed: int) -> None:
    from icmapper.data import gt
    from icmapper.data.sources import open_source
    from icmapper.data.types import RANGE_60x30

    rng = np.random.default_rng(seed)
    with RunWriter(path, method, "sim:val:1", RANGE_60x30) as w:
        for seq in open_source("sim:val:1", render=False):
            frames = []
            for t, g in enumerate(gt.sequence_gt(seq, RANGE_60x30)):
                k = len(g)
                keep = rng.random(k) > 0.1
                pts = (
                    g.points
                    + rng.normal(0, sigma, (k, 1, 2))
                    + rng.normal(0, sigma / 3, (k, 20, 2))
                )
                frames.append(
                    FramePredictions(
                        t, seq.poses[t], g.classes[keep], rng.uniform(0.5, 1, keep.sum()),
                        pts[keep].astype(np.float32), g.ids[keep], float(seq.timestamps[t]),
                    )
                )  # fmt: skip
            w.add_sequence(seq.name, frames)


def test_eval_prints_tables_and_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _noisy_run(tmp_path / "good", "gt+0.2m", 0.2, 0)
    _noisy_run(tmp_path / "bad", "gt+1m", 1.0, 1)
    from icmapper.cli import main

    out_json = tmp_path / "eval.json"
    rc = main(["eval", str(tmp_path / "good"), str(tmp_path / "bad"), "--json", str(out_json)])
    out = capsys.readouterr().out
    assert rc == 0
    assert "| gt+0.2m | 60x30 |" in out and "| gt+1m | 60x30 |" in out
    assert "MOTA_div" in out and "CD_div" in out
    res = json.loads(out_json.read_text())
    assert res["format"] == "icmapper-eval" and len(res["runs"]) == 2
    good, bad = res["runs"]
    assert good["detection"]["mAP"] > bad["detection"]["mAP"]
    assert good["tracking"]["mean"]["IDS"] == 0.0  # track ids are the GT ids
    assert good["consistency"]["C-mAP"] == pytest.approx(good["detection"]["mAP"])
