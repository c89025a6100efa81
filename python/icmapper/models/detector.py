"""The map detector (StreamMapNet-style): images + cameras + ego motion -> BEV -> map instances.

The streaming state (previous BEV and the propagated top-k queries) is passed explicitly:
``out, state = detector(images, intrinsics, cam_to_ego, state, prev_to_cur)``. Nothing is kept on
the module between calls.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import torch
from torch import nn

from icmapper.data.types import PerceptionRange, RANGE_60x30
from icmapper.models.backbone import ResNetBackbone
from icmapper.models.bev import BevNeck, TemporalMemory, ViewTransformer, sample_bev
from icmapper.models.config import ModelConfig
from icmapper.models.decoder import MapDecoder
from icmapper.models.propagation import QueryPropagation, select_topk
from icmapper.models.segmentation import SegHead, configured_line_radius
from icmapper.models.vectorise import VectorInstances, VectoriseParams, vectorise


@dataclass
class DetectorState:
    """Streaming state carried from one frame to the next (batch B).

    bev (B, C, X, Y) fused BEV of the previous frame; queries (B, k, C) and points (B, k, P, 2) in
    [0, 1] of the previous ego frame: the top-k queries; src_index (B, k) their query slots.
    """

    bev: torch.Tensor
    queries: torch.Tensor
    points: torch.Tensor
    src_index: torch.Tensor

    def detach(self) -> DetectorState:
        return DetectorState(
            self.bev.detach(), self.queries.detach(), self.points.detach(), self.src_index
        )


@dataclass
class DetectorOutput:
    """One frame of detections (batch B, Q queries, P points, K classes).

    logits / points: per decoder layer (B, Q, K) / (B, Q, P, 2) in [0, 1]; queries (B, Q, C) of the
    last layer; bev (B, C, X, Y). When queries were propagated: num_propagated = k (they occupy
    slots 0..k-1), prop_src (B, k) their slots in the previous frame, trans_points (B, k, P, 2)
    in [0, 1] the points regressed from the U_MLP output (for L_trans); else k = 0 and None.
    seg_logits (B, K, X, Y): the dense BEV segmentation of a model with ``seg_head`` (training's
    auxiliary target; computed in training mode only), else None. aux_logits / aux_points: per
    layer (B, A, K) / (B, A, P, 2), the one-to-many queries of a model with ``aux_queries`` in
    training mode, else None.
    """

    logits: list[torch.Tensor]
    points: list[torch.Tensor]
    queries: torch.Tensor
    bev: torch.Tensor
    num_propagated: int = 0
    prop_src: torch.Tensor | None = None
    trans_points: torch.Tensor | None = None
    seg_logits: torch.Tensor | None = None
    aux_logits: list[torch.Tensor] | None = None
    aux_points: list[torch.Tensor] | None = None

    def scores(self) -> torch.Tensor:
        """(B, Q) max class probability of the last layer."""
        return self.logits[-1].sigmoid().max(dim=-1).values

    def classes(self) -> torch.Tensor:
        """(B, Q) arg-max class of the last layer."""
        return self.logits[-1].argmax(dim=-1)


class MapDetector(nn.Module):
    """Backbone + view transformer + temporal memory + decoder + query propagation."""

    def __init__(self, cfg: ModelConfig, rng: PerceptionRange = RANGE_60x30) -> None:
        super().__init__()
        self.cfg = cfg
        self.rng = rng
        s = cfg
        hx, hy = rng.half_x, rng.half_y
        self.backbone = ResNetBackbone(s.backbone_widths, s.backbone_depths, s.channels)
        # channels-last convolutions run ~1.5x faster on CPU (oneDNN); same values
        self.backbone.to(memory_format=torch.channels_last)
        self.view = ViewTransformer(
            s.channels, s.channels, s.bev_x, s.bev_y, hx, hy, s.heights, s.num_cameras
        )
        self.neck = BevNeck(s.channels, s.bev_neck)
        self.memory = TemporalMemory(s.channels, hx, hy)
        self.seg = SegHead(s.channels, s.num_classes) if s.seg_head else None
        self.decoder = MapDecoder(
            s.channels,
            s.num_queries,
            s.num_layers,
            s.num_points,
            s.num_classes,
            s.heads,
            s.shared_reg,
            s.aux_queries,
            s.point_refine,
            (s.bev_x, s.bev_y),
        )
        self.propagation = QueryPropagation(s.channels, hx, hy)
        self.register_buffer("pix_mean", torch.tensor([0.45, 0.45, 0.45]).view(1, 3, 1, 1), False)
        self.register_buffer("pix_std", torch.tensor([0.25, 0.25, 0.25]).view(1, 3, 1, 1), False)

    # --- conversions -----------------------------------------------------------------------
    def to_metres(self, points01: torch.Tensor) -> torch.Tensor:
        """[0, 1] points (..., 2) -> ego metres (..., 2)."""
        half = points01.new_tensor([self.rng.half_x, self.rng.half_y])
        return (points01 * 2 - 1) * half

    def to_unit(self, points_m: torch.Tensor) -> torch.Tensor:
        """Ego metres (..., 2) -> [0, 1] of the range (not clamped)."""
        half = points_m.new_tensor([self.rng.half_x, self.rng.half_y])
        return (points_m / half + 1) / 2

    # --- stages ----------------------------------------------------------------------------
    def image_features(self, images: torch.Tensor) -> torch.Tensor:
        """images (B, N_cam, 3, H, W) uint8 or float in [0, 1] -> (B, N_cam, C, h, w)."""
        if images.dim() != 5 or images.shape[2] != 3:
            raise ValueError(f"images must be (B, N_cam, 3, H, W), got {tuple(images.shape)}")
        b, n = images.shape[:2]
        x = images.flatten(0, 1)  # (B*N, 3, H, W)
        x = x.float() / 255.0 if x.dtype == torch.uint8 else x.float()
        x = ((x - self.pix_mean) / self.pix_std).contiguous(memory_format=torch.channels_last)
        f = self.backbone(x)  # (B*N, C, h, w) channels-last, as the view transformer reads it
        return f.reshape(b, n, *f.shape[1:])

    def bev_features(
        self,
        feats: torch.Tensor,
        intrinsics: torch.Tensor,
        cam_to_ego: torch.Tensor,
        image_size: tuple[int, int],
        prev_bev: torch.Tensor | None,
        prev_to_cur: torch.Tensor | None,
    ) -> torch.Tensor:
        """BEV (B, C, X, Y) of this frame fused with the warped previous BEV (B, C, X, Y)."""
        bev = self.neck(self.view(feats, intrinsics, cam_to_ego, image_size))  # (B, C, X, Y)
        if not self.cfg.temporal or prev_bev is None or prev_to_cur is None:
            return self.memory(bev, None, None)
        cur_to_prev = torch.linalg.inv(prev_to_cur.float())  # (B, 4, 4)
        return self.memory(bev, prev_bev, cur_to_prev)

    def encode(
        self,
        images: torch.Tensor,
        intrinsics: torch.Tensor,
        cam_to_ego: torch.Tensor,
        prev_bev: torch.Tensor | None = None,
        prev_to_cur: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """The encoder half of ``forward``: images (B, N_cam, 3, H, W) -> fused BEV (B, C, X, Y)
        (``prev_bev``: the previous frame's fused BEV, None at a sequence start)."""
        image_size = (int(images.shape[-2]), int(images.shape[-1]))
        feats = self.image_features(images)  # (B, N, C, h, w)
        return self.bev_features(feats, intrinsics, cam_to_ego, image_size, prev_bev, prev_to_cur)

    def forward(
        self,
        images: torch.Tensor,
        intrinsics: torch.Tensor,
        cam_to_ego: torch.Tensor,
        state: DetectorState | None = None,
        prev_to_cur: torch.Tensor | None = None,
    ) -> tuple[DetectorOutput, DetectorState]:
        """One frame.

        images (B, N_cam, 3, H, W) uint8; intrinsics (B, N_cam, 3, 3); cam_to_ego (B, N_cam, 4, 4);
        state from the previous frame of the same sequences (None at a sequence start);
        prev_to_cur (B, 4, 4) previous ego -> current ego (= inv(pose_t) @ pose_{t-1}).
        Returns the detections and the state for the next frame.
        """
        bev, _ = self.encode_stream(images, intrinsics, cam_to_ego, state, prev_to_cur)
        return self.decode(bev, state, prev_to_cur)

    def encode_stream(
        self,
        images: torch.Tensor,
        intrinsics: torch.Tensor,
        cam_to_ego: torch.Tensor,
        state: DetectorState | None = None,
        prev_to_cur: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, DetectorState]:
        """``encode`` as one streaming frame, without the decoder: the fused BEV (B, C, X, Y) and
        a state that carries only it (no propagated queries: k = 0). With ``model.instances =
        "segmentation"`` the instances come from this BEV alone, so inference skips the set
        decoder; the BEV is the one ``forward`` makes (the memory reads only the previous BEV)."""
        if state is not None and prev_to_cur is None:
            raise ValueError("prev_to_cur is required when a state is given")
        prev_bev = state.bev if state is not None else None
        bev = self.encode(images, intrinsics, cam_to_ego, prev_bev, prev_to_cur)
        b, c = int(bev.shape[0]), int(bev.shape[1])
        empty = DetectorState(
            bev,
            bev.new_zeros((b, 0, c)),  # (B, 0, C)
            bev.new_zeros((b, 0, self.cfg.num_points, 2)),  # (B, 0, P, 2)
            torch.zeros((b, 0), dtype=torch.int64, device=bev.device),  # (B, 0)
        )
        return bev, empty

    def decode(
        self,
        bev: torch.Tensor,
        state: DetectorState | None = None,
        prev_to_cur: torch.Tensor | None = None,
    ) -> tuple[DetectorOutput, DetectorState]:
        """The decoder half of ``forward``: a fused BEV (B, C, X, Y) (``encode``) -> the
        detections and the state for the next frame (training on cached BEVs starts here)."""
        if state is not None and prev_to_cur is None:
            raise ValueError("prev_to_cur is required when a state is given")
        prop_q = prop_p = trans = src = None
        k = 0
        if self.cfg.propagate and state is not None and prev_to_cur is not None:
            prop_q, prop_p = self.propagation(state.queries, state.points, prev_to_cur)
            trans = self.decoder.refine(self.decoder.num_layers_ - 1, prop_q, prop_p)  # (B,k,P,2)
            src, k = state.src_index, int(state.queries.shape[1])
        dec = self.decoder(bev, prop_q, prop_p)
        seg = self.seg(bev) if self.seg is not None and self.training else None  # (B,K,X,Y)
        out = DetectorOutput(
            dec.logits,
            dec.points,
            dec.queries,
            bev,
            num_propagated=k,
            prop_src=src,
            trans_points=trans,
            seg_logits=seg,
            aux_logits=dec.aux_logits,
            aux_points=dec.aux_points,
        )
        return out, self.next_state(out)

    @torch.no_grad()
    def segment_instances(
        self, bev: torch.Tensor, params: VectoriseParams | None = None
    ) -> tuple[VectorInstances, torch.Tensor]:
        """Instances of one frame from the segmentation head (``model.instances =
        "segmentation"``): bev (1, C, X, Y) -> the vectorised instances (ego metres) and their
        embeddings (N, C) (``instance_embedding``)."""
        if self.seg is None:
            raise ValueError("the detector has no segmentation head (model.seg_head)")
        prob = self.seg(bev)[0].float().sigmoid().cpu().numpy()  # (K, X, Y)
        p = params or VectoriseParams()
        if p.shrink is None:  # crossings shrink by the targets' line radius
            p = replace(
                p, shrink=configured_line_radius(self.cfg, self.rng.half_x, self.rng.half_y)
            )
        if p.subcell is None:  # the lines this checkpoint's association and fusion were trained on
            p = replace(p, subcell=self.cfg.subcell)
        inst = vectorise(prob, self.rng.half_x, self.rng.half_y, p)
        pts = torch.as_tensor(inst.points, device=bev.device)  # (N, P, 2) metres
        return inst, self.instance_embedding(bev, pts[None])[0]

    def instance_embedding(self, bev: torch.Tensor, points_m: torch.Tensor) -> torch.Tensor:
        """The BEV features averaged along each instance: bev (B, C, X, Y), points_m (B, N, P, 2)
        ego metres -> (B, N, C) (the association's query of a vectorised instance)."""
        return sample_bev(bev, self.to_unit(points_m)).mean(dim=-2)  # (B, N, C)

    def next_state(self, out: DetectorOutput) -> DetectorState:
        """State for the next frame: the BEV and the top-k queries (by score) of ``out``."""
        k = min(self.cfg.topk, self.cfg.num_queries)
        idx = select_topk(out.scores().detach(), k)  # (B, k)
        q = torch.gather(out.queries, 1, idx[..., None].expand(-1, -1, out.queries.shape[-1]))
        pts = out.points[-1]  # (B, Q, P, 2)
        p = torch.gather(pts, 1, idx[..., None, None].expand(-1, -1, *pts.shape[2:]))
        return DetectorState(out.bev, q, p.detach(), idx)
