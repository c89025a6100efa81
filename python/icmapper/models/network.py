"""The whole IC-Mapper network and how to get one: built from its settings, or loaded from a
checkpoint for inference (nothing here imports the training package).

``ICMapperNet(model, rng)`` holds the three networks (one state dict for checkpoints): the detector
(``MapDetector``), the association head (``AssociationHead``) and the fusion module
(``FusionModule``), all built from one ``ModelConfig`` and the perception range.
``load_network(path)`` reads a checkpoint (``weights_only=True``) and returns the network in eval
mode with the settings it was trained with (``LoadedNetwork``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from torch import nn

from icmapper.data.types import PerceptionRange
from icmapper.models.association import AssociationHead
from icmapper.models.checkpoint import load_checkpoint
from icmapper.models.config import ModelConfig
from icmapper.models.detector import MapDetector
from icmapper.models.fusion import FusionModule
from icmapper.settings import from_table


class ICMapperNet(nn.Module):
    """detector (MapDetector), association (AssociationHead), fusion (FusionModule)."""

    def __init__(self, model: ModelConfig, rng: PerceptionRange) -> None:
        super().__init__()
        self.model_config = model
        self.rng = rng
        self.detector = MapDetector(model, rng)
        self.association = AssociationHead(model.channels, model.num_points)
        self.fusion = FusionModule(
            model.channels,
            model.num_points,
            rng.half_x,
            rng.half_y,
            margin=model.fusion_margin,
            num_layers=model.fusion_layers,
            heads=model.heads,
            num_classes=model.num_classes,
            history_points=model.fusion_history_points,
        )


@dataclass(frozen=True)
class LoadedNetwork:
    """A network read from a checkpoint, with the settings inference needs from its training
    config: the perception range, the image size (H, W) it was trained on and the detection
    score threshold."""

    net: ICMapperNet
    model: ModelConfig
    rng: PerceptionRange
    image_size: tuple[int, int]
    score_threshold: float
    stage: int
    step: int


def read_network_settings(
    config: dict[str, Any], path: str | Path
) -> tuple[ModelConfig, PerceptionRange, tuple[int, int], float]:
    """The inference settings stored in a checkpoint's plain config dict (the training config's
    ``[model]`` table, ``data.range``, ``data.image_size`` and ``score_threshold``); ValueError
    naming the checkpoint when one is missing or malformed."""
    try:
        model = from_table(ModelConfig, config.get("model", {}), "model")
        data = config["data"]
        rng = PerceptionRange.from_name(data["range"])
        h, w = (int(v) for v in data["image_size"])
        threshold = float(config["score_threshold"])
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise ValueError(f"checkpoint {path}: bad or missing config entry: {exc}") from None
    return model, rng, (h, w), threshold


def load_network(path: str | Path, device: str | torch.device = "cpu") -> LoadedNetwork:
    """The network of a checkpoint, on ``device``, in eval mode (see ``LoadedNetwork``).
    ValueError naming the file for a foreign, corrupt or mismatched checkpoint."""
    blob = load_checkpoint(path, map_location=device)
    model, rng, image_size, threshold = read_network_settings(blob["config"], path)
    net = ICMapperNet(model, rng)
    try:
        net.load_state_dict(blob["model"])
    except RuntimeError as exc:
        raise ValueError(f"checkpoint {path} does not fit its config: {exc}") from None
    return LoadedNetwork(
        net.to(device).eval(),
        model,
        rng,
        image_size,
        threshold,
        int(blob["stage"]),
        int(blob["step"]),
    )


def checkpoint_settings(path: str | Path) -> tuple[PerceptionRange, tuple[int, int]]:
    """(perception range, image size) of a checkpoint without building the network."""
    blob = load_checkpoint(path)
    _, rng, image_size, _ = read_network_settings(blob["config"], path)
    return rng, image_size


def checkpoint_training_source(path: str | Path) -> str:
    """The source spec a checkpoint was trained on (its training config's ``data.source``; ""
    when it does not say)."""
    data = load_checkpoint(path)["config"].get("data", {})
    return str(data.get("source", "")) if isinstance(data, dict) else ""


def _mapper_table(config: dict[str, Any], path: str | Path) -> dict[str, Any]:
    table = config.get("mapper", {})
    if not isinstance(table, dict):
        raise ValueError(f"checkpoint {path}: config [mapper] must be a table")
    return dict(table)


def checkpoint_mapper_settings(path: str | Path) -> dict[str, Any]:
    """The mapper settings a checkpoint carries (its training config's ``[mapper]`` table, as
    chosen on validation for this network; empty when it has none)."""
    return _mapper_table(load_checkpoint(path)["config"], path)


def checkpoint_mapper_defaults(path: str | Path) -> tuple[dict[str, Any], float]:
    """The ``[mapper]`` table and the detection score threshold of a checkpoint, from one read
    of the file (what ``MapperConfig.for_checkpoint`` starts from)."""
    config = load_checkpoint(path)["config"]
    return _mapper_table(config, path), read_network_settings(config, path)[3]
