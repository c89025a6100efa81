"""Training: tiny overfit, gradient flow per stage, determinism, checkpoints and resume, configs."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import torch
from icmapper.data.types import ego_to_world, world_to_ego
from icmapper.models.checkpoint import load_checkpoint, save_checkpoint
from icmapper.models.network import ICMapperNet
from icmapper.testing.clips import SyntheticClips, collate_clips
from icmapper.testing.configs import tiny_config
from icmapper.training.config import config_from_dict, config_to_dict, load_config
from icmapper.training.loop import train
from icmapper.training.objectives import Stage1Objective, Stage2Objective

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(autouse=True)
def _threads() -> None:
    torch.set_num_threads(1)


def _batch(cfg, clip_len: int | None = None) -> dict:
    ds = SyntheticClips(
        1,
        clip_len or cfg.data.clip_len,
        cfg.perception_range,
        cfg.data.image_size,
        cfg.model.num_cameras,
        seed=1,
    )
    return collate_clips([ds[0]])


class FakeMap:
    """Minimal stand-in of icmapper.GlobalMap for the stage-2 gradient test (last points per id)."""

    def __init__(self) -> None:
        self.items: dict[int, tuple[int, np.ndarray]] = {}

    def __contains__(self, i: int) -> bool:
        return i in self.items

    def insert_with_id(self, i: int, cls: int, pts: np.ndarray, frame: int = 0) -> None:
        self.items[i] = (cls, pts)

    def merge(self, i: int, pts: np.ndarray, frame: int = 0) -> None:
        self.items[i] = (self.items[i][0], pts)

    def get(self, i: int) -> tuple[int, np.ndarray]:
        return self.items[i]

    def info(self, i: int) -> dict:
        return {"observations": 1}

    def replace(self, i: int, pts: np.ndarray, frame: int = 0) -> None:
        from icmapper.geom import resample_many

        n = self.items[i][1].shape[0]  # keeps the sampled size of sample_patch
        self.items[i] = (self.items[i][0], resample_many(np.asarray(pts)[None], n, True)[0])

    def splice(self, i: int, pts: np.ndarray, overlap: float = 0.5, frame: int = 0) -> None:
        from icmapper.geom import resample_many, splice_polyline

        n = self.items[i][1].shape[0]  # keeps the sampled size of sample_patch
        new = splice_polyline(np.asarray(self.items[i][1], np.float64), pts, overlap)
        self.items[i] = (self.items[i][0], resample_many(new[None], n, False)[0])

    def sample_patch(self, pose, half, margin=20.0, n_points=20):
        x, y, yaw = pose
        c, s = np.cos(yaw), np.sin(yaw)
        m = np.eye(4)
        m[:2, :2] = [[c, -s], [s, c]]
        m[:2, 3] = [x, y]
        ids = np.array(list(self.items), dtype=np.uint64)
        cls = np.array([v[0] for v in self.items.values()], dtype=np.int64)
        from icmapper.geom import resample_many

        pts = np.array(
            [resample_many(world_to_ego(v[1], m)[None], n_points, v[0] == 0)[0]
             for v in self.items.values()], dtype=np.float32,
        ).reshape(-1, n_points, 2)  # fmt: skip
        return ids, cls, pts, np.ones(pts.shape[:2], dtype=bool)


def test_fake_map_frames_roundtrip() -> None:
    pose = np.eye(4)
    pose[:2, 3] = [3.0, -2.0]
    p = np.random.default_rng(0).random((20, 2))
    assert np.allclose(world_to_ego(ego_to_world(p, pose), pose), p)


def test_stage1_gradients_reach_trained_modules_only() -> None:
    cfg = tiny_config()
    torch.manual_seed(0)
    net = ICMapperNet(cfg.model, cfg.perception_range)
    obj = Stage1Objective(net, cfg)
    losses = obj(_batch(cfg, clip_len=3))
    assert set(losses) == {"loss", "det", "trans", "asso", "seg"}
    assert float(losses["seg"].detach()) == 0.0  # off unless stage1.seg_weight > 0
    assert all(torch.isfinite(v) for v in losses.values())
    losses["loss"].backward()
    for name, p in net.named_parameters():
        if name.startswith("fusion."):
            assert p.grad is None, name
        else:
            assert p.grad is not None and p.grad.abs().sum() > 0, f"no gradient for {name}"


def test_seg_head_and_neck_train() -> None:
    """With a BEV neck and the dense segmentation target, the auxiliary loss is positive and its
    gradient reaches the neck, the head and the view transformer (but the head is not run at
    inference)."""
    cfg = tiny_config(model={"bev_neck": 1, "seg_head": True}, stage1={"seg_weight": 1.0})
    torch.manual_seed(0)
    net = ICMapperNet(cfg.model, cfg.perception_range)
    obj = Stage1Objective(net, cfg)
    losses = obj(_batch(cfg, clip_len=2))
    assert float(losses["seg"].detach()) > 0
    losses["seg"].backward()
    for name in ("detector.seg.net.0.weight", "detector.neck.blocks.0.0.weight",
                 "detector.view.query"):  # fmt: skip
        grad = dict(net.named_parameters())[name].grad
        assert grad is not None and grad.abs().sum() > 0, name
    net.eval()
    b = _batch(cfg, clip_len=1)
    with torch.no_grad():
        out, _ = net.detector(b["images"][:, 0], b["intrinsics"][:, 0], b["cam_to_ego"][:, 0])
    assert out.seg_logits is None


def test_segmentation_only_stage1() -> None:
    """``stage1.decoder = false``: the same segmentation loss as the full objective on the same
    weights and clip (the same streamed BEV), the other losses 0, gradients for the encoder and
    the head only; the setting needs the segmentation instances and the loss."""
    seg = {"model": {"bev_neck": 1, "seg_head": True, "instances": "segmentation"}}
    cfg = tiny_config(**seg, stage1={"seg_weight": 1.0})
    only = tiny_config(**seg, stage1={"seg_weight": 1.0, "decoder": False})
    torch.manual_seed(0)
    net = ICMapperNet(cfg.model, cfg.perception_range)
    batch = _batch(cfg, clip_len=3)
    full = Stage1Objective(net, cfg)(batch)
    losses = Stage1Objective(net, only)(batch)
    torch.testing.assert_close(losses["seg"], full["seg"])
    assert all(float(losses[k]) == 0.0 for k in ("det", "trans", "asso"))
    torch.testing.assert_close(losses["loss"], full["seg"])
    net.zero_grad()
    losses["loss"].backward()
    grads = {n: p.grad for n, p in net.named_parameters()}
    assert grads["detector.view.query"].abs().sum() > 0
    assert grads["detector.seg.net.0.weight"].abs().sum() > 0
    assert all(g is None for n, g in grads.items() if n.startswith(("detector.decoder.",
               "detector.propagation.", "association.")))  # fmt: skip
    with pytest.raises(ValueError, match="decoder = false"):
        tiny_config(model={"seg_head": True}, stage1={"seg_weight": 1.0, "decoder": False})
    with pytest.raises(ValueError, match="decoder = false"):
        tiny_config(**seg, stage1={"decoder": False})


def test_one_to_many_loss_trains_the_aux_queries() -> None:
    cfg = tiny_config(model={"aux_queries": 5}, stage1={"one_to_many_repeats": 2})
    torch.manual_seed(0)
    net = ICMapperNet(cfg.model, cfg.perception_range)
    losses = Stage1Objective(net, cfg)(_batch(cfg, clip_len=2))
    assert float(losses["o2m"].detach()) > 0
    losses["o2m"].backward()
    grad = net.detector.decoder.query.grad  # (Q + A, C)
    assert grad is not None and grad[cfg.model.num_queries :].abs().sum() > 0
    assert grad[: cfg.model.num_queries].abs().sum() == 0  # main queries: not from this loss
    with pytest.raises(ValueError, match="one_to_many"):
        tiny_config(stage1={"one_to_many_repeats": 0})


def test_seg_weight_needs_seg_head() -> None:
    with pytest.raises(ValueError, match="seg_head"):
        tiny_config(stage1={"seg_weight": 1.0})
    with pytest.raises(ValueError, match="bev_neck"):
        tiny_config(model={"bev_neck": -1})
    with pytest.raises(ValueError, match="snapshot_every"):
        tiny_config(snapshot_every=-5)


def test_snapshots_are_inference_checkpoints(tmp_path: Path) -> None:
    from icmapper.models.network import load_network

    cfg = tiny_config(snapshot_every=2)
    train(cfg, 1, tmp_path, progress=False)
    snaps = sorted((tmp_path / "snapshots").glob("*.pt"))
    assert [p.name for p in snaps] == ["stage1_step000002.pt", "stage1_step000004.pt"]
    assert load_checkpoint(snaps[0])["optimizer"] is None
    assert load_network(snaps[-1]).step == 4


def test_amp_cpu_runs_the_objective_under_bf16_autocast(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``amp_cpu`` puts the training forward under CPU bf16 autocast; ``amp`` alone does not
    (it is for a GPU), and the losses stay finite."""
    seen: list[bool] = []
    forward = Stage1Objective.forward

    def recording(self: Stage1Objective, batch: dict) -> dict:
        if hasattr(torch, "get_autocast_dtype"):  # torch >= 2.4: the device-type argument
            seen.append(torch.is_autocast_enabled("cpu"))
        else:
            seen.append(torch.is_autocast_cpu_enabled())  # torch 2.2 / 2.3
        return forward(self, batch)

    monkeypatch.setattr(Stage1Objective, "forward", recording)
    res = train(tiny_config(amp_cpu=True), 1, tmp_path / "bf16", max_steps=2, progress=False)
    train(tiny_config(amp=True), 1, tmp_path / "fp32", max_steps=2, progress=False)
    assert seen == [True, True, False, False]
    assert all(np.isfinite(v) for v in res["losses"].values())


def test_stage2_gradients_reach_fusion_only() -> None:
    cfg = tiny_config()
    torch.manual_seed(0)
    net = ICMapperNet(cfg.model, cfg.perception_range)
    obj = Stage2Objective(net, cfg, map_factory=FakeMap)
    obj.train()
    assert not net.detector.training and net.fusion.training
    losses = obj(_batch(cfg, clip_len=3))
    assert float(losses["fused"]) > 0, "no detection had history: the test would be vacuous"
    losses["loss"].backward()
    for name, p in net.named_parameters():
        if name.startswith("fusion."):
            if "cls_embed" in name:
                continue  # only the classes present receive gradient
            assert p.grad is not None and p.grad.abs().sum() > 0, f"no gradient for {name}"
        else:
            assert p.grad is None, name


def test_tiny_overfit_losses_fall(tmp_path: Path) -> None:
    cfg = tiny_config(data={"source": "synthetic:1"}, stage1={"steps": 60, "lr": 3e-3})
    res = train(cfg, 1, tmp_path, progress=False)
    import csv

    rows = list(csv.DictReader((tmp_path / "stage1_metrics.csv").open()))
    first = np.mean([float(r["det"]) for r in rows[:5]])
    last = np.mean([float(r["det"]) for r in rows[-5:]])
    assert res["step"] == 60 and last < 0.6 * first, (first, last)


def test_determinism_and_resume(tmp_path: Path) -> None:
    cfg = tiny_config()
    a = train(cfg, 1, tmp_path / "a", progress=False)
    b = train(cfg, 1, tmp_path / "b", progress=False)
    assert a["param_digest"] == b["param_digest"]
    c = train(dataclasses.replace(cfg, seed=1), 1, tmp_path / "c", progress=False)
    assert c["param_digest"] != a["param_digest"]
    # 2 steps, then resume to 4: the same parameters as 4 steps straight
    train(cfg, 1, tmp_path / "r", max_steps=2, progress=False)
    assert load_checkpoint(tmp_path / "r" / "stage1.pt")["step"] == 2
    r = train(cfg, 1, tmp_path / "r", resume=True, progress=False)
    assert r["step"] == 4 and r["param_digest"] == a["param_digest"]


def test_checkpoint_roundtrip_and_errors(tmp_path: Path) -> None:
    cfg = tiny_config()
    net = ICMapperNet(cfg.model, cfg.perception_range)
    opt = torch.optim.AdamW(net.parameters())
    path = tmp_path / "x" / "ck.pt"
    save_checkpoint(
        path,
        model=net.state_dict(),
        optimizer=opt.state_dict(),
        stage=1,
        step=7,
        config=config_to_dict(cfg),
    )
    blob = load_checkpoint(path)
    assert blob["step"] == 7 and config_from_dict(blob["config"]) == cfg
    net2 = ICMapperNet(tiny_config().model, tiny_config().perception_range)
    net2.load_state_dict(blob["model"])
    for (k, v), (_, w) in zip(net.state_dict().items(), net2.state_dict().items(), strict=True):
        assert torch.equal(v, w), k
    (tmp_path / "bad.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError, match="bad.pt is unreadable") as err:
        load_checkpoint(tmp_path / "bad.pt")
    assert "weights_only=False" not in str(err.value)  # never advise unsafe loading
    # a pickle with arbitrary objects is refused (weights_only=True), never executed
    torch.save({"format": "icmapper-checkpoint", "obj": object()}, tmp_path / "evil.pt")
    with pytest.raises(ValueError, match="not a tensors-only"):
        load_checkpoint(tmp_path / "evil.pt")
    with pytest.raises(OSError):
        load_checkpoint(tmp_path / "missing.pt")


def test_stage2_loop_runs_from_stage1(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    cfg = tiny_config(stage2={"steps": 2, "clip_len": 3, "score_threshold": 0.0})
    train(cfg, 1, tmp_path, max_steps=1, progress=False)
    import icmapper.training.objectives as objectives

    orig = objectives.Stage2Objective.__init__

    def init(self, net, cfg, map_factory=None):  # the Rust GlobalMap may not be built yet
        orig(self, net, cfg, map_factory=FakeMap)

    monkeypatch.setattr(objectives.Stage2Objective, "__init__", init)
    before = load_checkpoint(tmp_path / "stage1.pt")["model"]
    res = train(cfg, 2, tmp_path, progress=False)
    after = load_checkpoint(tmp_path / "stage2.pt")["model"]
    assert res["step"] == 2
    det_keys = [k for k in before if k.startswith("detector.") and "running" not in k]
    assert all(torch.equal(before[k], after[k]) for k in det_keys)
    assert any(not torch.equal(before[k], after[k]) for k in before if k.startswith("fusion."))


def test_stage2_with_fresh_fusion_restarts_it_from_its_initial_weights(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``stage2.fresh_fusion``: a stage 2 from a trained checkpoint starts its fusion where a
    stage-1 run leaves it (the seeded initial weights), the rest as the checkpoint holds it."""
    import icmapper.training.objectives as objectives

    orig = objectives.Stage2Objective.__init__

    def init(self, net, cfg, map_factory=None):  # the Rust GlobalMap may not be built yet
        orig(self, net, cfg, map_factory=FakeMap)

    monkeypatch.setattr(objectives.Stage2Objective, "__init__", init)
    cfg = tiny_config(stage2={"steps": 2, "clip_len": 3, "score_threshold": 0.0})
    train(cfg, 1, tmp_path / "s1", max_steps=1, progress=False)
    stage1 = load_checkpoint(tmp_path / "s1" / "stage1.pt")["model"]
    train(cfg, 2, tmp_path / "s1", progress=False)  # a trained fusion
    trained = tmp_path / "s1" / "stage2.pt"
    captured: dict[str, dict[str, torch.Tensor]] = {}

    def capture(self, net, cfg, map_factory=None):
        captured["start"] = {k: v.clone() for k, v in net.state_dict().items()}
        orig(self, net, cfg, map_factory=FakeMap)

    monkeypatch.setattr(objectives.Stage2Objective, "__init__", capture)
    fresh = dataclasses.replace(cfg, stage2=dataclasses.replace(cfg.stage2, fresh_fusion=True))
    train(fresh, 2, tmp_path / "fresh", init=trained, progress=False)
    start, held = captured["start"], load_checkpoint(trained)["model"]
    for k, v in start.items():
        want = stage1[k] if k.startswith("fusion.") else held[k]
        assert torch.equal(v, want), k
    assert any(not torch.equal(stage1[k], held[k]) for k in stage1 if k.startswith("fusion."))
    train(cfg, 2, tmp_path / "kept", init=trained, progress=False)  # without: a fine-tune
    assert all(torch.equal(captured["start"][k], held[k]) for k in held if k.startswith("fusion."))

    # a fresh fusion of another shape (a finer view of the history) starts from the same file
    finer = dataclasses.replace(
        fresh, model=dataclasses.replace(fresh.model, fusion_history_points=7)
    )
    train(finer, 2, tmp_path / "finer", init=trained, max_steps=1, progress=False)
    start = captured["start"]
    assert start["fusion.embed_hist.index"].shape[0] == 7
    assert all(torch.equal(start[k], held[k]) for k in held if not k.startswith("fusion."))
    # without fresh_fusion the other shape is an error naming the checkpoint, not a crash later
    kept = dataclasses.replace(finer, stage2=dataclasses.replace(finer.stage2, fresh_fusion=False))
    with pytest.raises(ValueError, match="(?s)stage2.pt does not fit .*embed_hist"):
        train(kept, 2, tmp_path / "bad", init=trained, max_steps=1, progress=False)


def test_configs_load_and_validate(tmp_path: Path) -> None:
    small = load_config(REPO / "configs" / "small.toml")
    paper = load_config(REPO / "configs" / "paper.toml")
    assert small.model.num_queries == 30 and small.model.topk == 10
    assert (paper.model.num_queries, paper.model.num_points, paper.model.topk) == (100, 20, 33)
    assert paper.data.range == "60x30" and paper.score_threshold == 0.1
    bad = tmp_path / "bad.toml"
    for text, named in (
        ("[model]\nnum_querys = 3\n", "num_querys"),
        ("[model]\nchannels = 'x'\n", "channels"),
        ("[model]\ntopk = 99\n", "topk"),
        ("[data\n", "TOML"),
    ):
        bad.write_text(text)
        with pytest.raises(ValueError, match=named):
            load_config(bad)


def test_fine_tune_on_a_finer_bev_grid_starts_from_the_coarse_weights(tmp_path: Path) -> None:
    """``--init`` of a checkpoint with another BEV grid: the per-cell query is resampled
    (``regrid_state``), every other weight is copied as it is, and training runs."""
    from icmapper.models.checkpoint import regrid_state

    cfg = tiny_config()
    train(cfg, 1, tmp_path / "coarse", max_steps=1, progress=False)
    src = load_checkpoint(tmp_path / "coarse" / "stage1.pt")["model"]
    bx, by = cfg.model.bev_x, cfg.model.bev_y
    # lr 1e-12: the fine-tune's one step leaves the weights where the init put them
    fine = tiny_config(
        model={"bev_x": 2 * bx, "bev_y": 2 * by}, stage1={"lr": 1e-12, "weight_decay": 0.0}
    )
    res = train(fine, 1, tmp_path / "fine", init=tmp_path / "coarse" / "stage1.pt",
                max_steps=1, progress=False)  # fmt: skip
    got = load_checkpoint(res["checkpoint"])["model"]
    q = got["detector.view.query"]
    assert q.shape == (4 * bx * by, src["detector.view.query"].shape[1])
    # bilinear with cell centres aligned: twice as fine keeps the mean over the range, and the
    # corner cell reads the coarse corner cell
    fine_grid = q.reshape(2 * bx, 2 * by, -1)
    coarse = src["detector.view.query"].reshape(bx, by, -1)
    assert torch.allclose(fine_grid.mean((0, 1)), coarse.mean((0, 1)), atol=1e-6)
    assert torch.allclose(fine_grid[0, 0], coarse[0, 0], atol=1e-6)
    # every other weight as it was (batch norms' running statistics move with the step)
    stats = ("running_mean", "running_var", "num_batches_tracked")
    same = [k for k in src if k != "detector.view.query" and not k.endswith(stats)]
    assert same and all(torch.allclose(got[k], src[k], atol=1e-6) for k in same)
    # the same grid is left as it is; a table of the wrong size is refused by name
    assert regrid_state(src, (bx, by), (bx, by)) is src
    with pytest.raises(ValueError, match="detector.view.query"):
        regrid_state(src, (bx + 1, by), (bx, by))


def test_line_radius_sets_the_targets_and_the_crossing_shrink() -> None:
    """``model.line_radius`` (metres; 0: 0.75 of a cell) widens the segmentation targets, and the
    detector's vectoriser shrinks crossings by it unless told otherwise."""
    from icmapper.models.config import ModelConfig
    from icmapper.models.vectorise import VectoriseParams

    gts = [{"points": torch.tensor([[[-5.0, 0.0], [5.0, 0.0]]]), "classes": torch.tensor([1])}]
    cells = {}
    for radius in (0.0, 5.0):  # the tiny grid's cells are 3 m: 2.25 m by default
        cfg = tiny_config(model={"line_radius": radius})
        obj = Stage1Objective(ICMapperNet(cfg.model, cfg.perception_range), cfg)
        logits = torch.zeros(1, 3, cfg.model.bev_x, cfg.model.bev_y)
        cells[radius] = int(obj.seg_targets(gts, logits)[0, 1].sum())
    assert cells[5.0] > cells[0.0] > 0
    with pytest.raises(ValueError, match="line_radius"):
        ModelConfig(line_radius=-1.0)
    # the detector resolves an unset shrink to the configured radius (the grid's when 0)
    seen: list[float | None] = []
    import icmapper.models.detector as detector_mod

    real = detector_mod.vectorise

    def spy(prob, hx, hy, params=None):  # type: ignore[no-untyped-def]
        seen.append(params.shrink)
        return real(prob, hx, hy, params)

    cfg = tiny_config(model={"line_radius": 2.0, "seg_head": True})
    det = ICMapperNet(cfg.model, cfg.perception_range).detector.eval()
    bev = torch.zeros(1, cfg.model.channels, cfg.model.bev_x, cfg.model.bev_y)
    try:
        detector_mod.vectorise = spy
        det.segment_instances(bev)
        det.segment_instances(bev, VectoriseParams(shrink=0.3))
    finally:
        detector_mod.vectorise = real
    assert seen == [2.0, 0.3]
