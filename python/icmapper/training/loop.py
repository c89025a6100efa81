"""The training loop of both stages: data order, optimiser, schedule, AMP, DDP, logs, checkpoints.

``train(cfg, stage, out_dir, ...)`` runs stage 1 (detector + association on clips) or stage 2
(fusion on long clips / sequences, detector and association frozen, learning rate x lr_scale).
Checkpoints: ``OUT/stage{n}.pt`` (latest; resumable) and, with ``snapshot_every``, inference-only
snapshots ``OUT/snapshots/stage{n}_step{N}.pt`` (learning curves). Logs:
``OUT/stage{n}_metrics.csv`` and, when the ``tensorboard`` package is installed, ``OUT/tb``.
"""

from __future__ import annotations

import contextlib
import csv
import hashlib
import math
import os
import random
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch.nn.parallel import DistributedDataParallel
from torch.utils.data import DataLoader, Dataset

from icmapper.models.checkpoint import load_checkpoint, regrid_state, save_checkpoint
from icmapper.models.network import ICMapperNet
from icmapper.training.bevcache import (
    ENCODER_PARTS,
    BevClipDataset,
    collate_bev_clips,
    encode_sequences,
)
from icmapper.training.config import TrainConfig, config_to_dict, resolve_num_workers
from icmapper.training.distributed import DistInfo, barrier, init_distributed, mean_over_ranks
from icmapper.training.objectives import (
    SegAssociationObjective,
    Stage1Objective,
    Stage2Objective,
)


def param_digest(module: torch.nn.Module) -> str:
    """SHA-256 of all parameters' bytes in name order (replica identity checks)."""
    h = hashlib.sha256()
    for name, p in sorted(module.named_parameters()):
        h.update(name.encode())
        h.update(p.detach().cpu().contiguous().numpy().tobytes())
    return h.hexdigest()


def seed_everything(seed: int) -> None:
    """Seeds python and torch (numpy randomness always goes through seeded Generators)."""
    random.seed(seed)
    torch.manual_seed(seed)


#: Joins several ``open_source`` specs in ``data.source`` (spaces around it are optional).
SOURCE_JOIN = "+"


def training_sequences(cfg: TrainConfig) -> list[Any]:
    """The sequences of ``cfg.data.source`` (each of its " + "-joined specs in order) at the
    config's image size, seed and split file; ValueError for an empty part or a sequence name
    that two parts share (the image and BEV caches are keyed by it)."""
    from icmapper.data.sources import open_source

    specs = [part.strip() for part in cfg.data.source.split(SOURCE_JOIN)]
    if not all(specs):
        raise ValueError(f"data.source {cfg.data.source!r} has an empty part around '+'")
    seqs: list[Any] = []
    for spec in specs:
        seqs += open_source(
            spec,
            image_size=tuple(cfg.data.image_size),
            seed=cfg.seed,
            split_file=cfg.data.split_file or None,
        )
    names = [s.name for s in seqs]
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise ValueError(
            f"data.source {cfg.data.source!r} names sequences twice (e.g. {dup[0]!r}); "
            "give each spec once"
        )
    return seqs


def build_dataset(cfg: TrainConfig, stage: int) -> tuple[Dataset, Any]:
    """The clip dataset of ``cfg.data`` and its collate function.

    "synthetic:N" builds tiny random clips; any other spec goes through
    ``icmapper.data.sources.open_source`` and ``icmapper.data.datasets.ClipDataset``.
    """
    clip_len = cfg.data.clip_len if stage == 1 else cfg.stage2.clip_len
    spec = cfg.data.source
    if spec.startswith("synthetic:"):
        from icmapper.testing.clips import SyntheticClips, collate_clips

        try:
            num = int(spec.split(":", 1)[1])
        except ValueError:
            raise ValueError(f"bad data source {spec!r}; expected 'synthetic:N'") from None
        ds = SyntheticClips(
            num,
            clip_len,
            cfg.perception_range,
            cfg.data.image_size,
            cfg.model.num_cameras,
            seed=cfg.seed,
            num_points=cfg.model.num_points,
        )
        return ds, collate_clips
    try:
        from icmapper.data import datasets
    except ImportError as exc:
        raise RuntimeError(
            f"data source {spec!r} needs icmapper.data.datasets/sources, not available: {exc}"
        ) from None
    seqs = training_sequences(cfg)
    ds = datasets.ClipDataset(
        seqs,
        clip_len=clip_len,
        rng=cfg.perception_range,
        seed=cfg.seed,
        cache_dir=cfg.data.cache_dir or None,
    )
    return ds, datasets.collate_clips


def load_encoder(net: ICMapperNet, path: Path) -> None:
    """Starts a frozen-encoder run from checkpoint ``path``: its encoder parts
    (``bevcache.ENCODER_PARTS``) must fit ``net`` (ValueError naming the keys otherwise); every
    other tensor of the same name and shape is copied too (the rest keeps its fresh
    initialisation, e.g. a decoder of another architecture)."""
    state = load_checkpoint(path)["model"]
    prefixes = tuple(f"detector.{part}." for part in ENCODER_PARTS)
    own = net.state_dict()
    keys = [k for k in own if k.startswith(prefixes)]
    missing = [k for k in keys if k not in state]
    wrong = [k for k in keys if k in state and state[k].shape != own[k].shape]
    if missing or wrong:
        raise ValueError(
            f"checkpoint {path} does not hold this config's encoder: missing {missing[:3]}, "
            f"shape mismatch {wrong[:3]}"
        )
    fits = {k: v for k, v in state.items() if k in own and v.shape == own[k].shape}
    net.load_state_dict(fits, strict=False)


def bev_dataset(
    cfg: TrainConfig, net: ICMapperNet, out: Path, info: DistInfo | None = None, stage: int = 1
) -> tuple[Dataset, Any]:
    """The cached-BEV clips of ``cfg.data.source`` for ``stage``'s clip length (encoded now
    where the cache lacks them; with data-parallel ranks ``info``, each rank encodes its share and
    then reads the others')."""
    seqs = training_sequences(cfg)
    ranks = info is not None and info.enabled
    bevs = encode_sequences(
        net.detector,
        seqs,
        cfg.perception_range,
        cfg.data.bev_cache_dir or out / "bev-cache",
        tuple(cfg.data.image_size),
        image_cache=cfg.data.cache_dir or None,
        log=print if info is None or info.is_main else None,
        shard=(info.rank, info.world_size) if ranks and info is not None else (0, 1),
        wait=barrier if ranks else None,
    )
    clip_len = cfg.data.clip_len if stage == 1 else cfg.stage2.clip_len
    ds = BevClipDataset(seqs, bevs, clip_len, cfg.perception_range, seed=cfg.seed)
    return ds, collate_bev_clips


def epoch_batches(
    n: int, batch_size: int, epoch: int, seed: int, info: DistInfo
) -> list[list[int]]:
    """This rank's batches of one epoch: a seeded permutation, sharded by rank, last partial batch
    dropped (every rank gets the same number of batches)."""
    perm = np.random.default_rng([seed, epoch]).permutation(n)
    per_rank = n // info.world_size
    mine = perm[info.rank * per_rank : (info.rank + 1) * per_rank]
    count = per_rank // batch_size
    return [mine[i * batch_size : (i + 1) * batch_size].tolist() for i in range(count)]


def lr_at(step: int, base: float, warmup: int, total: int) -> float:
    """Linear warm-up then cosine decay to 1% of ``base``."""
    if warmup > 0 and step < warmup:
        return base * (step + 1) / warmup
    span = max(1, total - warmup)
    progress = min(1.0, (step - warmup) / span)
    return base * (0.01 + 0.99 * 0.5 * (1 + math.cos(math.pi * progress)))


def to_device(batch: dict, device: torch.device) -> dict:
    """Moves the tensors of a collated batch to ``device`` (gt stays where it is)."""
    return {k: (v.to(device) if isinstance(v, torch.Tensor) else v) for k, v in batch.items()}


class MetricsLog:
    """CSV metrics (rank 0) plus TensorBoard scalars when the package is available."""

    def __init__(self, path: Path, tb_dir: Path | None) -> None:
        self.path = path
        self.fields: list[str] | None = None
        if path.exists():
            with path.open(newline="") as fh:
                header = next(csv.reader(fh), None)
            self.fields = header
        self.tb = None
        if tb_dir is not None:
            with contextlib.suppress(ImportError):
                from torch.utils.tensorboard import SummaryWriter

                self.tb = SummaryWriter(str(tb_dir))

    def write(self, row: dict[str, float]) -> None:
        if self.fields is None:
            self.fields = list(row)
            with self.path.open("w", newline="") as fh:
                csv.writer(fh).writerow(self.fields)
        with self.path.open("a", newline="") as fh:
            csv.writer(fh).writerow([row.get(k, "") for k in self.fields])
        if self.tb is not None:
            for k, v in row.items():
                if k != "step":
                    self.tb.add_scalar(k, v, int(row["step"]))

    def close(self) -> None:
        if self.tb is not None:
            self.tb.close()


def _batches(
    ds: Dataset, collate: Any, cfg: TrainConfig, bs: int, start: int, info: DistInfo
) -> Iterator[tuple[int, dict]]:
    """(step, batch) from ``start`` on, epoch after epoch, in the seeded order."""
    n = len(ds)  # type: ignore[arg-type]
    spe = len(epoch_batches(n, bs, 0, cfg.seed, info))
    if spe == 0:
        raise ValueError(
            f"dataset of {n} clips is too small for batch size {bs} x {info.world_size} ranks"
        )
    step = start
    while True:
        epoch, offset = divmod(step, spe)
        chunks: Sequence[list[int]] = epoch_batches(n, bs, epoch, cfg.seed, info)[offset:]
        workers = resolve_num_workers(cfg.data.num_workers)
        loader = DataLoader(ds, batch_sampler=chunks, collate_fn=collate, num_workers=workers)
        for batch in loader:
            yield step, batch
            step += 1


def train(
    cfg: TrainConfig,
    stage: int,
    out_dir: str | Path,
    *,
    resume: bool = False,
    max_steps: int | None = None,
    init: str | Path | None = None,
    dataset: tuple[Dataset, Any] | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    """Runs one training stage.

    Returns {'step', 'losses' (last logged means), 'checkpoint', 'param_digest' (this rank's)}.

    stage 2 starts from ``init`` (default OUT/stage1.pt) unless it resumes its own checkpoint;
    stage 1 starts from ``init``'s weights when given (a fine-tune with a fresh optimizer and
    schedule; with ``freeze_encoder``, from its encoder).
    ``dataset`` (dataset, collate) overrides ``cfg.data.source``.
    """
    if stage not in (1, 2):
        raise ValueError(f"stage must be 1 or 2, got {stage}")
    out = Path(out_dir)
    info = init_distributed()
    seed_everything(cfg.seed)
    net = ICMapperNet(cfg.model, cfg.perception_range).to(info.device)
    ckpt_path = out / f"stage{stage}.pt"
    start = 0
    opt_state = None
    if resume and ckpt_path.exists():
        blob = load_checkpoint(ckpt_path)
        if blob["stage"] != stage:
            raise ValueError(f"{ckpt_path} is a stage {blob['stage']} checkpoint")
        net.load_state_dict(blob["model"])
        opt_state, start = blob["optimizer"], int(blob["step"])
        torch.set_rng_state(blob["rng"])
    elif stage == 2:
        src = Path(init) if init is not None else out / "stage1.pt"
        fresh = cfg.stage2.fresh_fusion  # the seeded initial fusion, whatever src holds
        state = load_checkpoint(src)["model"]
        if fresh:  # src's fusion is left out: it may be of another shape (model.fusion_*)
            state = {k: v for k, v in state.items() if not k.startswith("fusion.")}
            missing, unexpected = net.load_state_dict(state, strict=False)
            if unexpected or any(not k.startswith("fusion.") for k in missing):
                raise ValueError(
                    f"checkpoint {src} does not fit this config: missing "
                    f"{[k for k in missing if not k.startswith('fusion.')][:3]}, unexpected "
                    f"{unexpected[:3]}"
                )
        else:
            try:
                net.load_state_dict(state)
            except RuntimeError as err:  # e.g. a fusion of another shape
                raise ValueError(
                    f"checkpoint {src} does not fit this config (stage2.fresh_fusion = true "
                    f"starts a fusion of another shape afresh): {err}"
                ) from None
    elif cfg.stage1.freeze_encoder:
        if init is None:
            raise ValueError("stage1.freeze_encoder needs --init: the checkpoint of the encoder")
        load_encoder(net, Path(init))
    elif init is not None:  # a fine-tune: init's weights, a fresh optimizer and schedule
        blob = load_checkpoint(Path(init))
        own_grid = (cfg.model.bev_x, cfg.model.bev_y)
        src = blob.get("config", {}).get("model", {})
        src_grid = (src.get("bev_x", own_grid[0]), src.get("bev_y", own_grid[1]))
        # a finer or coarser BEV grid starts from the trained one (models.checkpoint.regrid_state)
        net.load_state_dict(regrid_state(blob["model"], src_grid, own_grid))
    if stage == 1 and cfg.stage1.freeze_encoder:
        for part in ENCODER_PARTS:
            module = getattr(net.detector, part)
            if module is not None:
                module.requires_grad_(False)
        if dataset is None:
            dataset = bev_dataset(cfg, net, out, info)
    if stage == 2 and cfg.stage2.cached_bev and dataset is None:
        dataset = bev_dataset(cfg, net, out, info, stage=2)  # the detector is frozen in stage 2
    kind: type[torch.nn.Module] = Stage1Objective if stage == 1 else Stage2Objective
    if stage == 1 and cfg.stage1.freeze_encoder and cfg.model.instances == "segmentation":
        kind = SegAssociationObjective  # the instances come from the frozen segmentation head
    objective = kind(net, cfg)
    objective.train()
    params = [p for p in objective.parameters() if p.requires_grad]
    s1 = cfg.stage1
    base_lr = s1.lr if stage == 1 else s1.lr * cfg.stage2.lr_scale
    warmup = s1.warmup_steps if stage == 1 else cfg.stage2.warmup_steps
    total = s1.steps if stage == 1 else cfg.stage2.steps
    horizon = total  # the schedule always spans the configured steps
    if max_steps is not None:
        total = min(total, max_steps)  # stop early; resuming continues the same schedule
    opt = torch.optim.AdamW(params, lr=base_lr, weight_decay=s1.weight_decay)
    if opt_state is not None:
        opt.load_state_dict(opt_state)
    model: torch.nn.Module = objective
    if info.enabled:
        model = DistributedDataParallel(
            objective,
            device_ids=[info.device.index] if info.device.type == "cuda" else None,
            find_unused_parameters=True,
        )
    ds, collate = dataset if dataset is not None else build_dataset(cfg, stage)
    dev_type = info.device.type
    amp = (cfg.amp and dev_type == "cuda") or (cfg.amp_cpu and dev_type == "cpu")
    log = None
    if info.is_main:
        out.mkdir(parents=True, exist_ok=True)
        log = MetricsLog(out / f"stage{stage}_metrics.csv", out / "tb")
    bar = None
    if progress and info.is_main:
        from icmapper.progress import progress as progress_bar

        bar = progress_bar(total, f"stage {stage}", unit="step", initial=start)
    sums: dict[str, float] = {}
    count = 0
    last: dict[str, float] = {}
    t0 = time.perf_counter()
    step = start
    batches = _batches(ds, collate, cfg, s1.batch_size, start, info) if start < total else iter(())
    for step, batch in batches:
        if step >= total:
            break
        lr = lr_at(step, base_lr, warmup, horizon)
        for group in opt.param_groups:
            group["lr"] = lr
        batch = to_device(batch, info.device)
        ctx = torch.autocast(dev_type, dtype=torch.bfloat16) if amp else contextlib.nullcontext()
        with ctx:
            losses = model(batch)
        if not torch.isfinite(losses["loss"].detach()):
            raise RuntimeError(f"non-finite loss at step {step}: {float(losses['loss'].detach())}")
        opt.zero_grad(set_to_none=True)
        losses["loss"].backward()
        torch.nn.utils.clip_grad_norm_(params, s1.grad_clip)
        opt.step()
        for k, v in losses.items():
            sums[k] = sums.get(k, 0.0) + float(v.detach())
        count += 1
        done = step + 1
        if done % cfg.log_every == 0 or done == total:
            means = mean_over_ranks({k: v / count for k, v in sums.items()}, info)
            dt = time.perf_counter() - t0
            row = {"step": done, "lr": lr, **means, "steps_per_s": count / max(dt, 1e-9)}
            if log is not None:
                log.write(row)
            last, sums, count, t0 = means, {}, 0, time.perf_counter()
        if bar is not None:
            bar.update(1)
            bar.set_postfix(loss=f"{float(losses['loss'].detach()):.3f}")
        if done % cfg.ckpt_every == 0 or done == total:
            if info.is_main:
                save_checkpoint(
                    ckpt_path,
                    model=net.state_dict(),
                    optimizer=opt.state_dict(),
                    stage=stage,
                    step=done,
                    config=config_to_dict(cfg),
                )
            barrier()
        if cfg.snapshot_every and done % cfg.snapshot_every == 0 and info.is_main:
            save_checkpoint(
                out / "snapshots" / f"stage{stage}_step{done:06d}.pt",
                model=net.state_dict(),
                optimizer=None,
                stage=stage,
                step=done,
                config=config_to_dict(cfg),
            )
        step = done
    if bar is not None:
        bar.close()
    if log is not None:
        log.close()
    return {
        "step": max(step, start),
        "losses": last,
        "checkpoint": str(ckpt_path),
        "param_digest": param_digest(net),
    }


def env_summary() -> str:
    """One line on the torch set-up (for logs)."""
    return (
        f"torch {torch.__version__}, threads {torch.get_num_threads()}, "
        f"cuda {torch.cuda.is_available()}, world {os.environ.get('WORLD_SIZE', '1')}"
    )
