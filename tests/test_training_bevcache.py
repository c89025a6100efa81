"""Decoder training on cached BEVs of a frozen encoder (icmapper.training.bevcache,
``stage1.freeze_encoder``, and stage 2's fusion with ``stage2.cached_bev``): the cache holds what
inference streams, the objectives give the same losses on cached BEVs as on images, the encoder
stays frozen, and the cache is reused or rebuilt."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from icmapper.data.datasets import ClipDataset, SequenceDataset, collate_clips
from icmapper.data.sources import open_source
from icmapper.models.checkpoint import load_checkpoint
from icmapper.testing.configs import tiny_raw
from icmapper.training.bevcache import (
    ENCODER_PARTS,
    BevClipDataset,
    collate_bev_clips,
    encode_sequences,
)
from icmapper.training.config import config_from_dict
from icmapper.training.loop import train
from icmapper.training.objectives import Stage1Objective, Stage2Objective, prev_to_cur

TINY = tiny_raw(
    model={"num_cameras": 6, "channels": 16, "point_refine": True},
    data={"source": "sim:val:1"},
    stage1={"steps": 2, "lr": 5e-4},
)


@pytest.fixture(autouse=True)
def _threads() -> None:
    torch.set_num_threads(1)


def _cfg(**stage1: object) -> object:
    return config_from_dict({**TINY, "stage1": {**TINY["stage1"], **stage1}})


@pytest.fixture(scope="module")
def encoder_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 2-step ordinary stage-1 run: the encoder checkpoint of the frozen runs."""
    out = tmp_path_factory.mktemp("encoder")
    train(_cfg(), 1, out, progress=False)
    return out / "stage1.pt"


def _net(cfg: object, ckpt: Path) -> object:
    from icmapper.models.network import ICMapperNet

    net = ICMapperNet(cfg.model, cfg.perception_range)
    net.load_state_dict(load_checkpoint(ckpt)["model"])
    return net.eval()


def test_cache_holds_the_streamed_bev(encoder_run: Path, tmp_path: Path) -> None:
    cfg = _cfg()
    net = _net(cfg, encoder_run)
    seqs = list(open_source("sim:val:1", image_size=(32, 64)))
    (bev,) = encode_sequences(net.detector, seqs, cfg.perception_range, tmp_path, (32, 64))
    item = SequenceDataset(seqs, cfg.perception_range)[0]
    state, poses = None, item["poses"][None]
    with torch.no_grad():
        for t in (0, 1, 2):
            motion = prev_to_cur(poses, t) if t > 0 else None
            out, state = net.detector(item["images"][None, t], item["intrinsics"][None, t],
                                      item["cam_to_ego"][None, t], state, motion)  # fmt: skip
            assert torch.equal(bev[t], out.bev[0].half())
    assert bev.shape == (len(seqs[0]), 16, 20, 10) and bev.dtype == torch.float16


def test_ranks_encode_their_share_of_the_cache(
    encoder_run: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """With data-parallel ranks each sequence is encoded once, by the rank whose share it is; the
    others read it from the cache after the barrier (two ranks played in turn in one process)."""
    import icmapper.training.bevcache as bevcache

    cfg = _cfg()
    net = _net(cfg, encoder_run)
    seqs = list(open_source("sim:val:3", image_size=(32, 64)))
    whole = encode_sequences(net.detector, seqs, cfg.perception_range, tmp_path / "a", (32, 64))
    calls: list[int] = []  # frames of each encoded sequence
    real = bevcache.encode_sequence

    def counted(detector: object, item: dict) -> torch.Tensor:
        calls.append(int(item["poses"].shape[0]))
        return real(detector, item)

    monkeypatch.setattr(bevcache, "encode_sequence", counted)
    root, size = tmp_path / "b", (32, 64)

    def rank0_then_barrier() -> None:  # rank 1 waits at the barrier while rank 0 runs
        assert len(calls) == 1  # rank 1 encoded its share: sequence 1
        bevs0 = encode_sequences(net.detector, seqs, cfg.perception_range, root, size,
                                 shard=(0, 2))  # fmt: skip
        assert len(calls) == 3  # rank 0: sequences 0 and 2; sequence 1 read from the cache
        assert all(torch.equal(a, b) for a, b in zip(bevs0, whole, strict=True))

    bevs1 = encode_sequences(net.detector, seqs, cfg.perception_range, root, size,
                             shard=(1, 2), wait=rank0_then_barrier)  # fmt: skip
    assert sorted(calls) == sorted(len(s) for s in seqs)  # each sequence encoded once
    assert all(torch.equal(a, b) for a, b in zip(bevs1, whole, strict=True))
    with pytest.raises(ValueError, match="bad shard"):
        encode_sequences(net.detector, seqs, cfg.perception_range, root, size, shard=(2, 2))


def test_objective_on_cached_bev_matches_images(encoder_run: Path, tmp_path: Path) -> None:
    cfg = _cfg()
    net = _net(cfg, encoder_run)
    seqs = list(open_source("sim:val:1", image_size=(32, 64)))
    bevs = encode_sequences(net.detector, seqs, cfg.perception_range, tmp_path, (32, 64))
    objective = Stage1Objective(net, cfg).eval()
    images = collate_clips([ClipDataset(seqs, 2, cfg.perception_range)[0]])
    cached = collate_bev_clips([BevClipDataset(seqs, bevs, 2, cfg.perception_range)[0]])
    assert cached["images"] is None and cached["bev"].shape == (1, 2, 16, 20, 10)
    with torch.no_grad():
        a, b = objective(images), objective(cached)
    for key in ("det", "trans", "asso"):
        assert float(b[key]) == pytest.approx(float(a[key]), rel=2e-2, abs=1e-3), key
    with pytest.raises(ValueError, match="needs bev"):
        objective({**cached, "bev": None})


def test_frozen_encoder_training(encoder_run: Path, tmp_path: Path) -> None:
    cfg = _cfg(freeze_encoder=True)
    with pytest.raises(ValueError, match="needs --init"):
        train(cfg, 1, tmp_path / "noinit", progress=False)
    train(cfg, 1, tmp_path, init=encoder_run, progress=False)
    before, after = load_checkpoint(encoder_run)["model"], load_checkpoint(tmp_path / "stage1.pt")
    after = after["model"]
    enc = [k for k in after if k.split(".")[1] in ENCODER_PARTS and k.startswith("detector.")]
    assert enc and all(torch.equal(before[k], after[k]) for k in enc)
    dec = [k for k in after if k.startswith("detector.decoder.")]
    assert any(not torch.equal(before[k], after[k]) for k in dec)
    files = sorted((tmp_path / "bev-cache").rglob("*.pt"))
    assert len(files) == 1
    stamp = files[0].stat().st_mtime_ns
    # a second run reads the cache; a corrupt file is rebuilt, never trusted
    train(cfg, 1, tmp_path / "again", init=encoder_run, progress=False)
    cached = dict(TINY["data"], bev_cache_dir=str(tmp_path / "bev-cache"))
    frozen = {**TINY["stage1"], "freeze_encoder": True}
    cfg2 = config_from_dict({**TINY, "data": cached, "stage1": frozen})
    train(cfg2, 1, tmp_path / "shared", init=encoder_run, progress=False)
    assert files[0].stat().st_mtime_ns == stamp
    files[0].write_bytes(b"not a torch file")
    train(cfg2, 1, tmp_path / "rebuilt", init=encoder_run, progress=False)
    assert torch.load(files[0], weights_only=True)["bev"].dtype == torch.float16
    assert not [p for p in files[0].parent.iterdir() if p.name.endswith(".tmp")]


def test_stage1_fine_tune_starts_from_init(encoder_run: Path, tmp_path: Path) -> None:
    """Stage 1 with ``init`` (and no freezing) starts from init's weights with a fresh schedule:
    one step at a vanishing learning rate leaves them as they were (batch-norm statistics aside);
    without ``init`` the run starts from its own initialisation."""
    cfg = _cfg(steps=1, lr=1e-12)
    train(cfg, 1, tmp_path / "ft", init=encoder_run, progress=False)
    before = load_checkpoint(encoder_run)["model"]
    blob = load_checkpoint(tmp_path / "ft" / "stage1.pt")
    assert int(blob["step"]) == 1
    weights = [k for k in before if "running_" not in k and "num_batches" not in k]
    for k in weights:
        torch.testing.assert_close(blob["model"][k], before[k], atol=1e-6, rtol=0)
    train(cfg, 1, tmp_path / "fresh", progress=False)
    fresh = load_checkpoint(tmp_path / "fresh" / "stage1.pt")["model"]
    assert any(not torch.allclose(fresh[k], before[k], atol=1e-6) for k in weights)


def test_frozen_encoder_needs_a_fitting_checkpoint(encoder_run: Path, tmp_path: Path) -> None:
    raw = {**TINY, "model": {**TINY["model"], "channels": 32}}
    cfg = config_from_dict({**raw, "stage1": {**TINY["stage1"], "freeze_encoder": True}})
    with pytest.raises(ValueError, match="does not hold this config's encoder"):
        train(cfg, 1, tmp_path, init=encoder_run, progress=False)


def test_joined_training_sources() -> None:
    """``data.source`` may join specs with '+': their sequences in order, clips over all of them;
    an empty part or a sequence named twice is a clear error."""
    from icmapper.training.loop import build_dataset, training_sequences

    cfg = config_from_dict(
        {"data": {"source": "sim:train:2 + sim-varied:train:1", "image_size": [16, 32]}}
    )
    names = [s.name for s in training_sequences(cfg)]
    plain = [s.name for s in open_source("sim:train:2", image_size=(16, 32))]
    assert names[:2] == plain and names[2].startswith("sim-varied-") and len(names) == 3
    ds, _ = build_dataset(cfg, stage=1)
    alone, _ = build_dataset(
        config_from_dict({"data": {"source": "sim:train:2", "image_size": [16, 32]}}), stage=1
    )
    assert len(ds) > len(alone)
    for bad, match in (("sim:train:2 +", "empty part"), ("sim:train:2+sim:train:2", "twice")):
        cfg = config_from_dict({"data": {"source": bad, "image_size": [16, 32]}})
        with pytest.raises(ValueError, match=match):
            training_sequences(cfg)


def _stage2_both_ways(net: object, cfg: object, tmp_path: Path) -> tuple:
    """Stage 2's objective on the first 4-frame clip of ``sim:val:1``, on images and on the BEVs
    the cache holds: (objective, the cached batch, the losses on images, on cached BEVs)."""
    seqs = list(open_source("sim:val:1", image_size=(32, 64)))
    bevs = encode_sequences(net.detector, seqs, cfg.perception_range, tmp_path / "c", (32, 64))
    objective = Stage2Objective(net, cfg).eval()
    images = collate_clips([ClipDataset(seqs, 4, cfg.perception_range)[0]])
    cached = collate_bev_clips([BevClipDataset(seqs, bevs, 4, cfg.perception_range)[0]])
    with torch.no_grad():
        a, b = objective(images), objective(cached)
    return objective, cached, a, b


def test_stage2_on_cached_bev(encoder_run: Path, tmp_path: Path) -> None:
    """Stage 2 reads the BEVs the cache holds: on a clip from the sequence start (where a clip's
    fresh memory and the streamed one agree) the fusion loss is the one on images, and a run
    trains the fusion and leaves the detector as it was."""
    cfg = _cfg()
    net = _net(cfg, encoder_run)
    objective, cached, a, b = _stage2_both_ways(net, cfg, tmp_path)
    assert float(a["fused"]) > 0 and float(b["fused"]) == float(a["fused"])
    assert float(b["fusion"]) == pytest.approx(float(a["fusion"]), rel=2e-2, abs=1e-4)
    with pytest.raises(ValueError, match="needs bev"):
        objective({**cached, "bev": None})
    stage2 = {"steps": 2, "clip_len": 4, "cached_bev": True, "lr_scale": 1.0}
    cache = dict(TINY["data"], bev_cache_dir=str(tmp_path / "bev-cache"))
    cfg2 = config_from_dict({**TINY, "data": cache, "stage2": stage2})
    train(cfg2, 2, tmp_path / "s2", init=encoder_run, progress=False)
    before = load_checkpoint(encoder_run)["model"]
    after = load_checkpoint(tmp_path / "s2" / "stage2.pt")["model"]
    det = [k for k in after if k.startswith("detector.")]
    assert det and all(torch.equal(before[k], after[k]) for k in det)
    assert any(not torch.equal(before[k], after[k]) for k in after if k.startswith("fusion."))
    assert len(sorted((tmp_path / "bev-cache").rglob("*.pt"))) == 1


def test_stage2_on_segmentation_instances_skips_the_decoder(tmp_path: Path) -> None:
    """With ``model.instances = "segmentation"`` stage 2 needs the BEV alone: the set decoder
    never runs (as at inference), on images or on cached BEVs, and both give the same loss."""
    from icmapper.models.network import ICMapperNet

    model = {**TINY["model"], "seg_head": True, "instances": "segmentation"}
    cfg = config_from_dict({**TINY, "model": model})
    torch.manual_seed(0)
    net = ICMapperNet(cfg.model, cfg.perception_range).eval()

    def no_decoder(*_: object, **__: object) -> None:
        raise AssertionError("the set decoder ran")

    net.detector.decoder.forward = no_decoder  # type: ignore[method-assign]
    _, _, a, b = _stage2_both_ways(net, cfg, tmp_path)
    assert float(b["fused"]) == float(a["fused"])
    assert float(b["fusion"]) == pytest.approx(float(a["fusion"]), rel=2e-2, abs=1e-4)
