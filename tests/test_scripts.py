"""The repository's scripts: each shell script parses, the GPU run's script refuses a bad phase
before it touches anything (it runs on a lent machine: scripts/gpu_paper.sh), and the mapping
experiment's stopped drives are what its --stop says."""

from __future__ import annotations

import importlib.util
import shutil
import subprocess
from pathlib import Path
from types import ModuleType

import pytest

REPO = Path(__file__).resolve().parents[1]
SCRIPTS = sorted((REPO / "scripts").glob("*.sh"))


def _script(name: str) -> ModuleType:
    """scripts/NAME.py imported as a module (the scripts are not a package)."""
    spec = importlib.util.spec_from_file_location(name, REPO / "scripts" / f"{name}.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("script", SCRIPTS, ids=[s.name for s in SCRIPTS])
def test_script_parses(script: Path) -> None:
    bash = shutil.which("bash")
    assert bash is not None
    done = subprocess.run([bash, "-n", str(script)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


@pytest.mark.parametrize("args", [[], ["train"], ["Start", "13"]])
def test_gpu_paper_refuses_a_bad_phase(args: list[str], tmp_path: Path) -> None:
    done = subprocess.run(
        ["bash", str(REPO / "scripts" / "gpu_paper.sh"), *args],
        capture_output=True, text=True, cwd=tmp_path,
        env={"PATH": "/usr/bin:/bin", "OUT": str(tmp_path / "out")},
    )  # fmt: skip
    assert done.returncode == 2
    assert "usage:" in done.stderr and "start MINUTES" in done.stderr
    assert not any(tmp_path.iterdir())  # nothing made before the check: no $OUT, no install


def test_map_experiment_stop_holds_the_middle_frame() -> None:
    """``scripts/map_experiment.py --stop N``'s drives: the middle frame held N more frames (its
    pose and images), the rest as they were, keyframes 0.5 s apart."""
    import numpy as np
    from icmapper.data.sources import open_source

    mod = _script("map_experiment")
    seq = open_source("sim:val:1", image_size=(32, 88))[0]
    t, k = len(seq), len(seq) // 2
    held = mod.with_stop(seq, 5)
    assert held.name == f"{seq.name}-stop5" and len(held) == t + 5
    poses = np.asarray(held.poses)
    for j in range(k, k + 6):
        np.testing.assert_array_equal(poses[j], seq.poses[k])
    np.testing.assert_array_equal(poses[: k + 1], seq.poses[: k + 1])
    np.testing.assert_array_equal(poses[k + 6 :], seq.poses[k + 1 :])
    np.testing.assert_allclose(np.diff(held.timestamps), 0.5)
    np.testing.assert_array_equal(held.frame(k + 3).images, seq.frame(k).images)


def test_map_experiment_coverage_floor() -> None:
    """``coverage_floor``: half the truth's mean distance to the nearest detected point, per
    class, averaged over drives; a class with truth and no detection in a drive is inf."""
    from types import SimpleNamespace

    import numpy as np

    mod = _script("map_experiment")

    def inst(cls: int, pts: list[list[float]], closed: bool = False) -> SimpleNamespace:
        return SimpleNamespace(cls=cls, points=np.asarray(pts, float), closed=closed)

    line = [[0.0, 0.0], [10.0, 0.0]]
    ring = [[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [0.0, 3.0]]
    gt = [inst(1, line), inst(2, [[0.0, 5.0], [10.0, 5.0]]), inst(0, ring, True)]
    seen = [
        (1, np.asarray([[0.0, 1.0], [10.0, 1.0]])),  # the lane line seen 1 m off
        (2, np.asarray([[0.0, 5.0], [5.0, 5.0]])),  # half of the kerb seen
        (0, np.asarray(ring) + [0.0, 2.0]),  # the crossing's ring 2 m off
    ]
    ped, div, bound = mod.coverage_floor([gt], [seen])
    assert div == pytest.approx(0.5)
    # the kerb's samples every 0.5 m (CD_STEP): 0 on the seen half, then 0.5 ... 5 m
    xs = np.linspace(0.0, 10.0, 21)
    assert bound == pytest.approx(0.5 * np.maximum(xs - 5.0, 0.0).mean())
    assert 0.0 < ped < 1.0
    # a second drive where nothing was detected: inf for its classes
    assert mod.coverage_floor([gt, gt], [seen, []])[1] == float("inf")


def test_diagnose_gap_finds_a_kerb_round_an_island() -> None:
    """``scripts/diagnose_gap.py``'s U column: a kerb up one side of a 2.5 m island, round its
    nose and down the other lies on itself; a straight kerb, an L and a U too short do not."""
    import numpy as np

    mod = _script("diagnose_gap")
    nose = np.stack(
        [1.25 * np.sin(np.linspace(0, np.pi, 9)), 1.25 * np.cos(np.linspace(0, np.pi, 9))], 1
    )
    island = np.concatenate([[[-30.0, 1.25]], nose, [[-30.0, -1.25]]])  # 30 m each side
    assert mod.lies_on_itself(island)
    assert not mod.lies_on_itself(np.array([[0.0, 0.0], [60.0, 0.0]]))
    assert not mod.lies_on_itself(np.array([[0.0, 0.0], [30.0, 0.0], [30.0, 30.0]]))
    short = np.concatenate([[[-4.0, 1.25]], nose, [[-4.0, -1.25]]])  # 4 m each side
    assert not mod.lies_on_itself(short)
    # coverage: a map holding one side of the island leaves the other side 2.5 m off
    side = np.array([[-30.0, -1.25], [0.0, -1.25]])
    d = mod.coverage(island, [side])
    assert d.min() < 1e-9 and 2.4 < d.max() < 2.6  # sample to sample
    np.testing.assert_allclose(mod.coverage(side, [side]), 0.0, atol=1e-9)
    assert np.isinf(mod.coverage(side, [])).all()


def test_plot_verify_draws_kept_removed_and_cut(tmp_path: Path) -> None:
    """scripts/plot_verify.py's picture from a hand-made map and verdict: a PNG is written
    atomically (nothing else left in the folder) and names the verdict's counts in its title."""
    from types import SimpleNamespace

    import numpy as np
    from icmapper import GlobalMap
    from icmapper.mapping.verify import Verdict

    mod = _script("plot_verify")
    gm = GlobalMap()
    line = np.stack([np.arange(0.0, 30.0), np.zeros(30)], -1)  # (30, 2)
    kept = gm.insert(1, line)
    gone = gm.insert(1, line + [0.0, 6.0])
    ring = gm.insert(0, np.array([[5.0, 3.0], [9.0, 3.0], [9.0, 5.0], [5.0, 5.0]]))
    verdict = Verdict(removed=[gone], trimmed={kept: (3, 25)})
    gt = [SimpleNamespace(points=line, closed=False)]
    poses = np.tile(np.eye(4), (5, 1, 1))  # (5, 4, 4)
    poses[:, 0, 3] = np.arange(5.0) * 5
    title = mod.draw(gm, verdict, gt, poses, tmp_path / "v.png", "hand-made")
    assert [p.name for p in tmp_path.iterdir()] == ["v.png"]
    assert (tmp_path / "v.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "1 instances removed, 1 with ends cut" in title and ring in gm.ids().tolist()


def test_map_experiment_reestimate_moves_lines_to_the_mean_of_their_views() -> None:
    """``reestimate`` (``--reestimate GATE``): each point of a map line goes to the mean of the
    nearest points of the same-class detections within the gate, one per detection; points no
    detection reached, other classes' views and crossings stay as they were."""
    import numpy as np

    mod = _script("map_experiment")
    x = np.linspace(0.0, 10.0, 11)
    line = np.c_[x, np.full_like(x, 0.3)]  # a lane line drawn 0.3 m left of y = 0
    ring = np.array([[0.0, 5.0], [4.0, 5.0], [4.0, 8.0], [0.0, 8.0]])
    items = [(1, line, False, 3.0), (0, ring, True, 2.0)]
    dets = [
        (1, np.c_[x[:6], np.zeros(6)]),  # two views of its first half, at y = 0 and 0.2
        (1, np.c_[x[:6], np.full(6, 0.2)]),
        (2, np.c_[x, np.full_like(x, 0.25)]),  # a kerb view: another class
        (1, np.c_[x, np.full_like(x, 3.0)]),  # the next lane line, beyond the gate
        (0, ring + 0.5),
    ]
    out = mod.reestimate(items, dets, 1.0)
    assert [(k, closed, obs) for k, _, closed, obs in out] == [(1, False, 3.0), (0, True, 2.0)]
    moved = out[0][1]
    np.testing.assert_allclose(moved[:6], np.c_[x[:6], np.full(6, 0.1)], atol=1e-9)
    np.testing.assert_allclose(moved[7:], line[7:])  # no view within 1 m (x = 6 is 1.0 away)
    np.testing.assert_array_equal(out[1][1], ring)


def test_map_experiment_bev_cache_belongs_to_the_encoder() -> None:
    """``bev_cache_dir``: keyed by the encoder's parameters, the image size and the source, so a
    checkpoint whose fusion alone was retrained reads the BEVs already cached, and a changed
    encoder never does."""
    import torch
    from icmapper.models.network import ICMapperNet
    from icmapper.testing.configs import tiny_config

    mod = _script("map_experiment")
    torch.manual_seed(0)
    cfg = tiny_config()
    net = ICMapperNet(cfg.model, cfg.perception_range)
    key = mod.bev_cache_dir("/c", net.detector, (32, 88), "sim:val:4")
    with torch.no_grad():
        next(net.fusion.parameters()).add_(1.0)
    assert mod.bev_cache_dir("/c", net.detector, (32, 88), "sim:val:4") == key
    assert mod.bev_cache_dir("/c", net.detector, (64, 176), "sim:val:4") != key
    assert mod.bev_cache_dir("/c", net.detector, (32, 88), "sim:val:12") != key
    assert mod.bev_cache_dir("/c", net.detector, (32, 88), "sim:val:4", hz=4.0) != key
    with torch.no_grad():
        next(net.detector.backbone.parameters()).add_(1.0)
    assert mod.bev_cache_dir("/c", net.detector, (32, 88), "sim:val:4") != key


def test_map_experiment_methods_in_any_order(tiny_checkpoint: Path, tmp_path: Path) -> None:
    """The other methods replay the detections the full mapper records: asked without it, or
    before it, they get the same detections and the same figures as after it."""
    import json

    mod = _script("map_experiment")
    common = ["--source", "sim:val:1", "--checkpoint", str(tiny_checkpoint)]
    common += ["--cache", str(tmp_path / "bev")]
    out = {}
    for methods in ("post-track,icmapper-base", "icmapper,icmapper-base,post-track"):
        f = tmp_path / f"{methods}.json"
        assert mod.main([*common, "--methods", methods, "--json", str(f)]) == 0
        out[methods] = json.loads(f.read_text())
    alone, after = out["post-track,icmapper-base"], out["icmapper,icmapper-base,post-track"]
    assert set(alone) == {"post-track", "icmapper-base"}
    for n in alone:
        assert alone[n]["detection"] == after[n]["detection"]
        assert alone[n]["mapping"] == after[n]["mapping"]


def test_map_experiment_refuses_an_unknown_method_before_any_work(tmp_path: Path) -> None:
    """A misspelt method is refused at once, naming the known ones (it used to fail only after the
    detections of the first drive were recorded)."""
    mod = _script("map_experiment")
    with pytest.raises(SystemExit):
        mod.main(["--source", "sim:val:1", "--methods", "post-track,bogus",
                  "--cache", str(tmp_path / "bev")])  # fmt: skip
    assert not (tmp_path / "bev").exists()
