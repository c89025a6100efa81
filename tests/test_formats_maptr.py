"""MapTR / MapTRv2 result files (formats/maptr.py): class names in MapTR's order, centerline left
out, nuScenes points in the LIDAR_TOP frame converted with the scene's calibration (perfect
predictions written in the lidar frame score AP 1), bad files."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from icmapper.data import gt as gt_mod
from icmapper.data.sources import open_source
from icmapper.data.types import CLASS_NAMES, RANGE_60x30
from icmapper.formats import PredictionFileError, read_predictions
from icmapper.formats.source import PredictionInput
from icmapper.testing.nuscenes_fixture import write_nuscenes_fixture

VERSION = "v1.0-mini"
#: MapTR's label order (projects/configs/maptrv2/*.py: map_classes).
MAPTR_CLASSES = ["divider", "ped_crossing", "boundary"]
LIDAR_YAW, LIDAR_T = -math.pi / 2, (0.9, 0.2)  # nuScenes' LIDAR_TOP: x right, y forward


@pytest.fixture(scope="module")
def nus(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = write_nuscenes_fixture(tmp_path_factory.mktemp("nus") / "nus", VERSION)
    cal_path = root / VERSION / "calibrated_sensor.json"
    cal = json.loads(cal_path.read_text())
    for c in cal:
        if c["token"] == "c_lidar":
            c["rotation"] = [math.cos(LIDAR_YAW / 2), 0.0, 0.0, math.sin(LIDAR_YAW / 2)]
            c["translation"] = [*LIDAR_T, 1.8]
    cal_path.write_text(json.dumps(cal))
    return root


def _sample_tokens(root: Path) -> dict[str, list[str]]:
    scenes = json.loads((root / VERSION / "scene.json").read_text())
    samples = {s["token"]: s for s in json.loads((root / VERSION / "sample.json").read_text())}
    out = {}
    for sc in scenes:
        toks, tok = [], sc["first_sample_token"]
        while tok:
            toks.append(tok)
            tok = samples[tok]["next"]
        out[sc["name"]] = toks
    return out


def _results(root: Path, drop: int | None = None) -> tuple[dict, str]:
    """GT of every frame as MapTR results in the lidar frame (closed crossings, MapTR labels), plus
    a centerline; ``drop``: leave frame 0 of the first scene out."""
    spec = f"nuscenes:{root}"
    seqs = open_source(spec, render=False)
    tokens = _sample_tokens(root)
    c, s = math.cos(LIDAR_YAW), math.sin(LIDAR_YAW)
    rot = np.array([[c, -s], [s, c]])
    results = []
    for seq in seqs:
        for t, g in enumerate(gt_mod.sequence_gt(seq, RANGE_60x30)):
            if drop is not None and seq is seqs[0] and t == drop:
                continue
            vecs = []
            for cls, pts in zip(g.classes, g.points.astype(np.float64), strict=True):
                lidar = (pts - np.array(LIDAR_T)) @ rot  # ego -> lidar: R^T (p - t)
                if cls == 0:
                    lidar = np.concatenate([lidar, lidar[:1]])
                name = CLASS_NAMES[cls]
                vecs.append(
                    {
                        "pts": lidar.tolist(),
                        "pts_num": len(lidar),
                        "cls_name": name,
                        "type": MAPTR_CLASSES.index(name),
                        "confidence_level": 0.9,
                    }
                )
            vecs.append(
                {
                    "pts": [[0, 0], [1, 0]],
                    "pts_num": 2,
                    "cls_name": "centerline",
                    "type": 3,
                    "confidence_level": 0.8,
                }
            )
            results.append({"sample_token": tokens[seq.name][t], "vectors": vecs})
    return {"meta": {"use_camera": True}, "results": results}, spec


def test_lidar_frame_predictions_score_perfectly(nus: Path, tmp_path: Path) -> None:
    data, spec = _results(nus)
    path = tmp_path / "nuscmap_results.json"
    path.write_text(json.dumps(data))
    preds = read_predictions(path)
    assert preds.format == "maptr" and preds.point_frame == "lidar"
    seqs = open_source(spec, render=False)
    inp = PredictionInput(preds, spec, seqs)
    for seq in seqs:
        gts = gt_mod.sequence_gt(seq, RANGE_60x30)
        for f, g in zip(inp.frames(seq), gts, strict=True):
            np.testing.assert_array_equal(f.classes, g.classes)  # centerline left out
            np.testing.assert_allclose(f.points, g.points, atol=1e-4)  # back in the ego frame
    from icmapper.eval.evaluate import evaluate_predictions

    r = evaluate_predictions(f"file:{path}", spec, sources=seqs)
    assert r["detection"]["mAP"] == pytest.approx(1.0)
    assert r["num_predictions"] == r["num_gt"]


def test_missing_frame_and_bad_classes(nus: Path, tmp_path: Path) -> None:
    data, spec = _results(nus, drop=0)
    path = tmp_path / "m.json"
    path.write_text(json.dumps(data))
    seqs = open_source(spec, render=False)
    inp = PredictionInput(read_predictions(path), spec, seqs)
    with pytest.raises(PredictionFileError, match=f"no predictions for frame 0 .*{seqs[0].name}"):
        inp.frames(seqs[0])
    bad = json.loads(json.dumps(data))
    bad["results"][0]["vectors"][0]["cls_name"] = "lane_divider"
    path.write_text(json.dumps(bad))
    with pytest.raises(PredictionFileError, match="unknown class name 'lane_divider'"):
        read_predictions(path, "maptr")
    bad["results"][0]["vectors"][0].update(cls_name="divider", pts_num=1)
    path.write_text(json.dumps(bad))
    with pytest.raises(PredictionFileError, match="pts_num 1"):
        read_predictions(path)
