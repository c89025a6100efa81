"""The network's settings: one frozen dataclass, ``ModelConfig``, the ``[model]`` table of a
training config and of every checkpoint. The detector, the association head and the fusion module
are all built from it (``icmapper.models.network.ICMapperNet``); nothing else restates them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: The values of ``ModelConfig.instances``.
INSTANCE_SOURCES = ("decoder", "segmentation")


@dataclass(frozen=True)
class ModelConfig:
    """Network hyper-parameters (with the perception range, everything the networks are built
    from). Range checks run on construction (ValueError naming the key)."""

    num_cameras: int = 6
    backbone_widths: tuple[int, ...] = (16, 32, 64)
    backbone_depths: tuple[int, ...] = (1, 1, 1)
    channels: int = 64
    bev_x: int = 50  # BEV cells along x (forward)
    bev_y: int = 25  # BEV cells along y (left)
    heights: tuple[float, ...] = (-1.0, 0.0, 1.0, 2.0)  # metres sampled per BEV pillar
    num_queries: int = 30
    num_layers: int = 3  # decoder layers
    num_points: int = 20  # points per instance
    num_classes: int = 3
    heads: int = 4
    shared_reg: bool = True  # one regression head shared by the decoder layers
    topk: int = 10  # queries propagated to the next frame
    temporal: bool = True  # BEV memory (GRU) across frames
    propagate: bool = True  # query propagation (U_MLP) across frames
    fusion_layers: int = 3
    fusion_margin: float = 20.0  # metres around the range from which history is sampled
    fusion_history_points: int = 20  # points per sampled history instance
    bev_neck: int = 0  # residual 3x3 conv blocks on each frame's BEV (spatial context)
    seg_head: bool = False  # dense BEV segmentation head (auxiliary training target, MapTRv2)
    #: extra decoder queries for one-to-many matching (MapTRv2's hybrid matching; training only)
    aux_queries: int = 0
    #: per-point refinement from each point's 3x3 BEV neighbourhood (``models.decoder``)
    point_refine: bool = False
    #: where inference takes the instances from: "decoder" (the set decoder's queries) or
    #: "segmentation" (the dense head's masks, vectorised: ``models.vectorise``; needs seg_head)
    instances: str = "decoder"
    #: metres: the segmentation targets' line radius (and the vectoriser's crossing shrink); 0:
    #: 0.75 of the larger BEV cell side (``segmentation.target_line_radius``)
    line_radius: float = 0.0
    #: line classes whose vectorised points the detector moves to the probabilities' maximum
    #: between the cells (``VectoriseParams.subcell``, ``models.subcell``); the association and
    #: the fusion of a checkpoint are trained on the instances this gives
    subcell: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        positive = (
            "channels", "bev_x", "bev_y", "num_queries", "num_layers", "num_points",
            "num_cameras", "fusion_layers", "fusion_history_points", "heads",
        )  # fmt: skip
        for key in positive:
            if not getattr(self, key) > 0:
                raise ValueError(
                    f"config key model.{key} must be positive, got {getattr(self, key)}"
                )
        if not (math.isfinite(self.line_radius) and self.line_radius >= 0):
            raise ValueError(f"config key model.line_radius must be >= 0, got {self.line_radius}")
        if not all(isinstance(k, int) and 0 < k < self.num_classes for k in self.subcell):
            raise ValueError(
                f"config key model.subcell must hold line class indices (1-{self.num_classes - 1}),"
                f" got {self.subcell}"
            )
        if self.channels % self.heads:
            raise ValueError(f"model.channels ({self.channels}) must be divisible by model.heads")
        if not 0 <= self.topk <= self.num_queries:
            raise ValueError(f"model.topk must be in [0, num_queries], got {self.topk}")
        if len(self.backbone_widths) != len(self.backbone_depths) or len(self.backbone_widths) < 2:
            raise ValueError(
                "model.backbone_widths and backbone_depths must have equal length >= 2"
            )
        if self.instances not in INSTANCE_SOURCES:
            raise ValueError(
                f"model.instances must be one of {INSTANCE_SOURCES}, got {self.instances!r}"
            )
        if self.instances == "segmentation" and not self.seg_head:
            raise ValueError('model.instances = "segmentation" needs model.seg_head = true')
        if self.aux_queries < 0:
            raise ValueError(f"model.aux_queries must be >= 0, got {self.aux_queries}")
        if self.bev_neck < 0:
            raise ValueError(f"model.bev_neck must be >= 0, got {self.bev_neck}")
        if not self.fusion_margin >= 0:
            raise ValueError(f"model.fusion_margin must be >= 0, got {self.fusion_margin}")
