"""Training configuration: TOML files loaded into validated, frozen dataclasses.

A config has the tables [model], [data], [stage1], [stage2] and top-level keys (name, seed, amp,
amp_cpu, ...). Unknown keys and bad values raise ``ValueError`` naming the key.
``config_to_dict`` gives plain Python data (stored in checkpoints).
"""

from __future__ import annotations

import dataclasses
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from icmapper.data.types import PerceptionRange
from icmapper.models.config import ModelConfig
from icmapper.settings import from_table, to_plain

#: The most DataLoader workers ``data.num_workers = -1`` chooses (the value the paper and
#: real-data configs set; each worker holds a copy of the dataset's state and its decode buffers).
AUTO_WORKERS_MAX = 8


def resolve_num_workers(num_workers: int, cores: int | None = None) -> int:
    """The DataLoader worker count of ``data.num_workers``: itself when >= 0; for -1 the cores
    (``cores``, default the CPUs this process may run on) less one for the training process, at
    least 0 and at most ``AUTO_WORKERS_MAX``. Per process: each rank of a multi-GPU run on one
    machine takes as many."""
    if num_workers >= 0:
        return num_workers
    if num_workers != -1:
        raise ValueError(f"num_workers must be >= 0 or -1, got {num_workers}")
    if cores is None:
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None
        cores = cores or os.cpu_count() or 1
    return max(0, min(cores - 1, AUTO_WORKERS_MAX))


@dataclass(frozen=True)
class DataConfig:
    """Where clips come from: ``source`` is an ``open_source`` spec ("sim:train:64", "av2:PATH"),
    several joined by " + " (their sequences together, clips drawn uniformly over all of them:
    "sim:train:128 + sim-varied:train:128"), or "synthetic:N" (tiny random clips for tests and
    benchmarks)."""

    source: str = "sim:train:16"
    clip_len: int = 3
    range: str = "60x30"
    image_size: tuple[int, int] = (64, 176)
    #: DataLoader worker processes; -1 chooses them from the cores (``resolve_num_workers``: the
    #: cores this process may use less one for the training loop, at most ``AUTO_WORKERS_MAX``).
    num_workers: int = 0
    #: On-disk image cache folder (icmapper.data.datasets.ImageCache), "" for none; one per size.
    cache_dir: str = ""
    #: Folder of the BEV cache of ``stage1.freeze_encoder`` runs, "" for OUT/bev-cache.
    bev_cache_dir: str = ""
    #: Split file for a source spec naming a split ("nuscenes:PATH:train"), "" for PATH/splits.json.
    split_file: str = ""


@dataclass(frozen=True)
class Stage1Config:
    """Detector + association (+ query transfer): L_det + alpha L_trans + beta L_asso."""

    lr: float = 5e-4
    weight_decay: float = 0.01
    batch_size: int = 2
    steps: int = 2000
    warmup_steps: int = 100
    grad_clip: float = 35.0
    alpha_trans: float = 1.0
    beta_asso: float = 1.0
    cls_weight: float = 2.0
    pts_weight: float = 5.0
    detach_state: bool = True
    #: weight of the dense BEV segmentation loss (needs model.seg_head; 0: off)
    seg_weight: float = 0.0
    #: one-to-many matching (needs model.aux_queries > 0): GT repeats and the loss weight
    one_to_many_repeats: int = 6
    one_to_many_weight: float = 1.0
    #: false: stage 1 trains only the encoder and the segmentation head, on the segmentation
    #: loss (``model.instances = "segmentation"`` needs nothing else at inference; the set
    #: decoder, the query propagation and the stage-1 association are left untrained), a faster
    #: step (BENCHMARKS.md). The shipped checkpoint's stage 1 sets it false (its README).
    decoder: bool = True
    #: train the decoder, query propagation and association on cached BEVs of a frozen encoder
    #: taken from ``--init`` (``icmapper.training.bevcache``); the segmentation loss is off
    freeze_encoder: bool = False


@dataclass(frozen=True)
class Stage2Config:
    """Fusion on whole sequences with the global map built online: lambda L_fusion; the learning
    rate is ``lr_scale`` times stage 1's."""

    lr_scale: float = 0.1
    steps: int = 500
    warmup_steps: int = 20
    clip_len: int = 20
    lambda_fusion: float = 1.0
    score_threshold: float = 0.1
    match_threshold: float = 0.1
    #: read the frozen detector's BEVs from the BEV cache (``icmapper.training.bevcache``, the
    #: one the association run of the same encoder fills) instead of running the encoder: each
    #: frame's BEV as inference streams it, the memory carried from the sequence start rather
    #: than reset at each clip; the detector takes about two thirds of a step on the CPU
    cached_bev: bool = False
    #: start the fusion from its initial weights (the seeded ones a stage-1 run leaves it at)
    #: whatever ``--init`` holds: a stage 2 retrained from a trained checkpoint, such as the
    #: shipped one, after the mapper or the vectoriser changed what the fusion sees
    fresh_fusion: bool = False


@dataclass(frozen=True)
class TrainConfig:
    """A whole training configuration."""

    name: str = "small"
    seed: int = 0
    amp: bool = True  # bf16 autocast of the training forward on a GPU
    #: the same on the CPU: 1.14-1.2x a stage-1 step on a CPU with native bf16 (AVX-512 BF16 /
    #: AMX); the losses of 2,250 steps and the AP of 3,000 as in float32 (BENCHMARKS.md); slower
    #: on a CPU without it. On in the shipped checkpoint's stage 1 (--set), off in its later steps.
    amp_cpu: bool = False
    log_every: int = 10
    ckpt_every: int = 200
    #: every N steps also keep an inference-only copy OUT/snapshots/stage{n}_step{N:06d}.pt, for
    #: learning curves (``python -m icmapper.training.curves``); 0: none
    snapshot_every: int = 0
    score_threshold: float = 0.1
    model: ModelConfig = field(default_factory=ModelConfig)
    data: DataConfig = field(default_factory=DataConfig)
    stage1: Stage1Config = field(default_factory=Stage1Config)
    stage2: Stage2Config = field(default_factory=Stage2Config)
    #: The ``[mapper]`` table: ``MapperConfig`` settings chosen on validation for this network
    #: (e.g. ``min_hits``). Stored in the checkpoint; ``icmapper map`` / ``compare`` and
    #: ``Mapper.from_checkpoint`` start from them (``--set`` still overrides).
    mapper: dict[str, Any] = field(default_factory=dict)

    @property
    def perception_range(self) -> PerceptionRange:
        return PerceptionRange.from_name(self.data.range)


_TABLES = {"model": ModelConfig, "data": DataConfig, "stage1": Stage1Config, "stage2": Stage2Config}


def _validate(cfg: TrainConfig) -> None:
    d, s1, s2 = cfg.data, cfg.stage1, cfg.stage2
    positive = {
        "data.clip_len": d.clip_len,
        "stage1.batch_size": s1.batch_size,
        "stage1.lr": s1.lr,
        "stage2.lr_scale": s2.lr_scale,
        "stage2.clip_len": s2.clip_len,
        "log_every": cfg.log_every,
        "ckpt_every": cfg.ckpt_every,
    }
    for key, v in positive.items():
        if not v > 0:
            raise ValueError(f"config key {key} must be positive, got {v}")
    if len(d.image_size) != 2 or min(d.image_size) < 16:
        raise ValueError(f"data.image_size must be [H, W] >= 16, got {list(d.image_size)}")
    if d.num_workers < -1:
        raise ValueError("data.num_workers must be >= 0, or -1 to choose from the cores")
    cfg.perception_range  # noqa: B018 - validates data.range
    for key, v in {
        "score_threshold": cfg.score_threshold,
        "stage2.score_threshold": s2.score_threshold,
    }.items():
        if not 0.0 <= v <= 1.0:
            raise ValueError(f"config key {key} must be in [0, 1], got {v}")
    if cfg.snapshot_every < 0:
        raise ValueError(f"config key snapshot_every must be >= 0, got {cfg.snapshot_every}")
    if s1.one_to_many_repeats < 1 or s1.one_to_many_weight < 0:
        raise ValueError("stage1.one_to_many_repeats must be >= 1 and one_to_many_weight >= 0")
    if s1.seg_weight < 0:
        raise ValueError(f"config key stage1.seg_weight must be >= 0, got {s1.seg_weight}")
    if s1.seg_weight > 0 and not cfg.model.seg_head:
        raise ValueError("config key stage1.seg_weight > 0 needs model.seg_head = true")
    if not s1.decoder and (s1.seg_weight <= 0 or cfg.model.instances != "segmentation"):
        raise ValueError(
            "config key stage1.decoder = false needs stage1.seg_weight > 0 and "
            'model.instances = "segmentation" (the instances then come from the segmentation '
            "head alone)"
        )
    if s1.steps < 0 or s2.steps < 0 or s1.warmup_steps < 0 or s2.warmup_steps < 0:
        raise ValueError("steps and warmup_steps must be >= 0")


def config_from_dict(raw: dict[str, Any]) -> TrainConfig:
    """Builds and validates a config from a (TOML-shaped) dict."""
    from icmapper.mapping.config import MapperConfig

    top = {k: v for k, v in raw.items() if k not in (*_TABLES, "mapper")}
    for name in (*_TABLES, "mapper"):
        if name in raw and not isinstance(raw[name], dict):
            raise ValueError(f"config [{name}] must be a table")
    tables = {name: from_table(cls, raw.get(name, {}), name) for name, cls in _TABLES.items()}
    mapper = dict(raw.get("mapper", {}))
    MapperConfig.from_dict(mapper)  # unknown names and wrong types fail here, not at inference
    base = from_table(TrainConfig, top, "top level") if top else TrainConfig()
    cfg = dataclasses.replace(base, **tables, mapper=mapper)
    _validate(cfg)
    return cfg


def apply_overrides(raw: dict[str, Any], overrides: dict[str, Any]) -> dict[str, Any]:
    """A copy of a TOML-shaped config dict with ``{"data.image_size": [64, 176], "seed": 1}``
    style overrides set (dotted names reach the tables; ``settings.parse_assignments`` parses
    ``--set NAME=VALUE`` items into such a dict). Unknown keys fail in ``config_from_dict``."""
    out = {k: (dict(v) if isinstance(v, dict) else v) for k, v in raw.items()}
    for name, value in overrides.items():
        table, dot, key = name.rpartition(".")
        if not dot:
            out[key] = value
        elif table in _TABLES or table == "mapper":
            out.setdefault(table, {})[key] = value
        else:
            raise ValueError(
                f"bad override {name!r}: unknown table {table!r} ({', '.join(_TABLES)})"
            )
    return out


def load_config(path: str | Path, overrides: dict[str, Any] | None = None) -> TrainConfig:
    """Reads a TOML config file, then applies ``overrides`` (``apply_overrides``); ValueError on
    bad content, OSError when unreadable."""
    if sys.version_info < (3, 11):  # pragma: no cover
        raise RuntimeError("TOML configs need Python >= 3.11 (tomllib)")
    import tomllib

    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"config {path}: bad TOML: {exc}") from None
    try:
        return config_from_dict(apply_overrides(raw, overrides or {}))
    except ValueError as exc:
        raise ValueError(f"config {path}: {exc}") from None


def config_to_dict(cfg: TrainConfig) -> dict[str, Any]:
    """Plain nested dict (tuples as lists) of a config; ``config_from_dict`` inverts it."""
    return to_plain(cfg)
