"""Tiny training configurations for tests and demos: ``tiny_config(**tables)`` is a
``TrainConfig`` small enough to train a few steps in seconds on one CPU thread (2 cameras at
32x64, 8-16 channels, a 20x10 BEV, 8 queries, tiny random clips); each keyword names a table (or
a top-level key) whose entries replace the defaults'."""

from __future__ import annotations

from typing import Any

from icmapper.training.config import TrainConfig, config_from_dict

#: The defaults of ``tiny_config`` (a TOML-shaped dict).
TINY: dict[str, Any] = {
    "log_every": 1,
    "ckpt_every": 100,
    "model": {
        "num_cameras": 2,
        "backbone_widths": [8, 16],
        "backbone_depths": [1, 1],
        "channels": 32,
        "bev_x": 20,
        "bev_y": 10,
        "num_queries": 8,
        "num_layers": 2,
        "topk": 3,
    },
    "data": {"source": "synthetic:2", "clip_len": 2, "image_size": [32, 64]},
    "stage1": {"batch_size": 1, "steps": 4, "warmup_steps": 0, "lr": 2e-3},
    "stage2": {"clip_len": 3, "score_threshold": 0.0},
}


def tiny_raw(**tables: Any) -> dict[str, Any]:
    """``TINY`` with the given tables merged in (a dict value updates that table, any other value
    replaces a top-level key)."""
    raw = {k: (dict(v) if isinstance(v, dict) else v) for k, v in TINY.items()}
    for key, value in tables.items():
        if isinstance(value, dict):
            raw[key] = {**raw.get(key, {}), **value}
        else:
            raw[key] = value
    return raw


def tiny_config(**tables: Any) -> TrainConfig:
    """The validated ``TrainConfig`` of ``tiny_raw(**tables)``."""
    return config_from_dict(tiny_raw(**tables))
