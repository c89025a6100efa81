"""The two training objectives of ``ICMapperNet`` (icmapper.models.network).

``Stage1Objective``: detector + association on clips -> L_det + alpha L_trans + beta L_asso.
``Stage2Objective``: fusion on sequences with the global map built online (Rust engine) while
detector and association stay frozen -> lambda L_fusion.
Both are ``nn.Module``s whose forward(batch) returns a dict of losses (``"loss"`` is the total), so
that DDP wraps them directly.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import torch
from torch import nn

from icmapper.data.types import MapClass, ego_to_world, pose_to_xy_yaw
from icmapper.mapping.config import MapperConfig
from icmapper.mapping.crossings import CrossingMerger
from icmapper.mapping.passed import merge_view
from icmapper.models.detector import DetectorOutput, DetectorState, MapDetector
from icmapper.models.losses import (
    DetectionCriterion,
    FrameMatch,
    association_loss,
    association_targets,
    fusion_loss,
    repeat_targets,
    trans_loss,
)
from icmapper.models.network import ICMapperNet
from icmapper.models.propagation import select_topk, transform_points
from icmapper.models.segmentation import configured_line_radius, rasterise, seg_loss
from icmapper.training.config import TrainConfig


def prev_to_cur(poses: torch.Tensor, t: int) -> torch.Tensor:
    """Ego motion previous -> current frame: poses (B, T, 4, 4) float64 ego->world -> (B, 4, 4)
    float32 = inv(pose_t) @ pose_{t-1}."""
    return (torch.linalg.inv(poses[:, t]) @ poses[:, t - 1]).float()


def frame_cameras(batch: dict, t: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Frame t of a clip batch as the detector takes it: images (B, N, 3, H, W), intrinsics
    (B, N, 3, 3), cam_to_ego (B, N, 4, 4)."""
    return batch["images"][:, t], batch["intrinsics"][:, t], batch["cam_to_ego"][:, t]


def prepare_gt(gt: dict, detector: MapDetector, device: torch.device) -> dict:
    """A frame's GT dict on ``device`` with 'points01' ([0, 1] of the range) added."""
    pts = gt["points"].to(device=device, dtype=torch.float32)  # (G, P, 2)
    if pts.numel() and not torch.isfinite(pts).all():
        raise ValueError("ground-truth points contain NaN or inf")
    return {
        "ids": gt["ids"].to(device),
        "classes": gt["classes"].to(device),
        "points": pts,
        "points01": detector.to_unit(pts),
    }


def check_batch(batch: dict) -> None:
    """Shape checks of a collated clip batch (clear errors for bad input); a batch of cached
    BEVs (``training.bevcache``) has ``bev`` (B, T, C, X, Y) and no images."""
    img = batch["images"]
    if img is None:
        bev = batch.get("bev")
        if bev is None or bev.dim() != 5:
            shape = None if bev is None else tuple(bev.shape)
            raise ValueError(f"a batch without images needs bev (B, T, C, X, Y), got {shape}")
        b, t = bev.shape[:2]
        c = batch["intrinsics"].shape[2]
    elif img.dim() != 6 or img.shape[3] != 3:
        raise ValueError(f"batch images must be (B, T, C, 3, H, W), got {tuple(img.shape)}")
    else:
        b, t, c = img.shape[:3]
    expect = {"intrinsics": (b, t, c, 3, 3), "cam_to_ego": (b, t, c, 4, 4), "poses": (b, t, 4, 4)}
    for key, shape in expect.items():
        if tuple(batch[key].shape) != shape:
            raise ValueError(f"batch {key} must be {shape}, got {tuple(batch[key].shape)}")
    if len(batch["gt"]) != b or any(len(g) != t for g in batch["gt"]):
        raise ValueError("batch gt must be a list (B) of lists (T)")


class Stage1Objective(nn.Module):
    """forward(batch) -> {'loss', 'det', 'trans', 'asso', 'seg'} averaged over the clip's frames
    ('seg': the dense BEV segmentation loss, 0 unless ``stage1.seg_weight`` > 0; with
    ``model.aux_queries`` > 0 also 'o2m', the one-to-many detection loss).

    With ``stage1.decoder = false`` only the encoder and the segmentation head train: each frame
    is ``MapDetector.encode_stream`` (the same BEV and memory, without the set decoder, the query
    propagation and the association) and the loss is the segmentation loss alone ('det',
    'trans', 'asso' are 0)."""

    def __init__(self, net: ICMapperNet, cfg: TrainConfig) -> None:
        super().__init__()
        s = cfg.stage1
        self.detector = net.detector
        self.association = net.association
        self.criterion = DetectionCriterion(cfg.model.num_classes, s.cls_weight, s.pts_weight)
        self.alpha, self.beta = s.alpha_trans, s.beta_asso
        self.seg_weight = s.seg_weight
        self.o2m_repeats, self.o2m_weight = s.one_to_many_repeats, s.one_to_many_weight
        self.o2m = net.detector.cfg.aux_queries > 0
        self.detach_state = s.detach_state
        self.train_decoder = s.decoder

    def seg_targets(self, gts: list[dict], seg_logits: torch.Tensor) -> torch.Tensor:
        """Rasterised GT of one frame (B, K, X, Y) on the BEV grid of ``seg_logits``."""
        det = self.detector
        _, k, nx, ny = seg_logits.shape
        r = det.rng
        radius = configured_line_radius(det.cfg, r.half_x, r.half_y)
        return torch.stack(
            [rasterise(g["points"], g["classes"], nx, ny, r.half_x, r.half_y, k, radius)
             for g in gts]
        )  # fmt: skip

    def association_pairs(
        self,
        out: DetectorOutput,
        match: FrameMatch,
        prev: DetectorOutput,
        prev_match: FrameMatch,
        motion: torch.Tensor,
        b: int,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Association logits (D, T) and GT match matrix for sample b.

        Detected: the matched queries plus the unmatched among the top-k by score (ids -1);
        tracked: the previous frame's matched queries, points moved into the current frame.
        """
        det = self.detector
        q_all = out.queries.shape[1]
        ids = torch.full((q_all,), -1, dtype=torch.int64, device=out.queries.device)
        ids[match.pred_idx] = match.gt_ids
        top = select_topk(out.scores()[b : b + 1].detach(), det.cfg.topk)[0]  # (k,)
        slots = torch.unique(torch.cat([match.pred_idx, top]))  # (D,)
        trk = prev_match.pred_idx  # (T,)
        p_det = out.points[-1][b, slots]  # (D, P, 2)
        p_trk_m = det.to_metres(prev.points[-1][b, trk].detach())  # (T, P, 2)
        p_trk = det.to_unit(transform_points(p_trk_m[None], motion[b : b + 1])[0])  # (T, P, 2)
        logits = self.association(
            out.queries[b : b + 1, slots], p_det[None], prev.queries[b : b + 1, trk], p_trk[None]
        )[0]  # (D, T)
        return logits, association_targets(ids[slots], prev_match.gt_ids)

    def forward(self, batch: dict) -> dict[str, torch.Tensor]:
        check_batch(batch)
        if not self.train_decoder:
            return self.segmentation_only(batch)
        cached = batch["images"] is None  # cached BEVs of a frozen encoder (training.bevcache)
        first = batch["bev"] if cached else batch["images"]  # (B, T, ...)
        dev, t_len = first.device, first.shape[1]
        state: DetectorState | None = None
        prev: DetectorOutput | None = None
        prev_matches: list[FrameMatch] | None = None
        zero = first.new_zeros((), dtype=torch.float32)
        l_det, l_trans, l_asso, l_seg, l_o2m = zero, zero, zero, zero, zero
        n_asso = 0
        for t in range(t_len):
            motion = prev_to_cur(batch["poses"], t) if t > 0 else None
            if cached:
                out, nxt = self.detector.decode(batch["bev"][:, t], state, motion)
            else:
                out, nxt = self.detector(*frame_cameras(batch, t), state, motion)
            gts = [prepare_gt(g[t], self.detector, dev) for g in batch["gt"]]
            det_loss, matches = self.criterion(out.logits, out.points, gts)
            l_det = l_det + det_loss
            if out.aux_logits is not None and out.aux_points is not None:
                rep = [repeat_targets(g, self.o2m_repeats) for g in gts]
                l_o2m = l_o2m + self.criterion(out.aux_logits, out.aux_points, rep)[0]
            if self.seg_weight > 0 and out.seg_logits is not None and not cached:
                l_seg = l_seg + seg_loss(out.seg_logits, self.seg_targets(gts, out.seg_logits))
            if out.trans_points is not None and out.prop_src is not None and prev_matches:
                l_trans = l_trans + trans_loss(out.trans_points, out.prop_src, prev_matches, gts)
            if prev is not None and prev_matches is not None and motion is not None:
                for b in range(len(gts)):
                    logits, target = self.association_pairs(
                        out, matches[b], prev, prev_matches[b], motion, b
                    )
                    l_asso = l_asso + association_loss(logits, target)
                    n_asso += 1
            state = nxt.detach() if self.detach_state else nxt
            prev, prev_matches = out, matches
        l_det = l_det / t_len
        l_trans = l_trans / max(1, t_len - 1)
        l_asso = l_asso / max(1, n_asso)
        l_seg = l_seg / t_len
        l_o2m = l_o2m / t_len
        total = l_det + self.alpha * l_trans + self.beta * l_asso + self.seg_weight * l_seg
        total = total + self.o2m_weight * l_o2m
        losses = {"loss": total, "det": l_det, "trans": l_trans, "asso": l_asso, "seg": l_seg}
        return {**losses, "o2m": l_o2m} if self.o2m else losses

    def segmentation_only(self, batch: dict) -> dict[str, torch.Tensor]:
        """``stage1.decoder = false``: the segmentation loss of every frame, the BEV streamed by
        ``encode_stream``; the other losses are 0."""
        det, seg_head = self.detector, self.detector.seg
        if seg_head is None or batch["images"] is None:
            raise ValueError("stage1.decoder = false needs a segmentation head and images")
        dev, t_len = batch["images"].device, batch["images"].shape[1]
        state: DetectorState | None = None
        l_seg = batch["images"].new_zeros((), dtype=torch.float32)
        for t in range(t_len):
            motion = prev_to_cur(batch["poses"], t) if t > 0 else None
            bev, nxt = det.encode_stream(*frame_cameras(batch, t), state, motion)
            logits = seg_head(bev)  # (B, K, X, Y)
            gts = [prepare_gt(g[t], det, dev) for g in batch["gt"]]
            l_seg = l_seg + seg_loss(logits, self.seg_targets(gts, logits))
            state = nxt.detach() if self.detach_state else nxt
        l_seg = l_seg / t_len
        zero = l_seg.new_zeros(())
        losses = {"loss": self.seg_weight * l_seg, "det": zero, "trans": zero, "asso": zero}
        return {**losses, "seg": l_seg, **({"o2m": zero} if self.o2m else {})}


def gt_ids_of(
    points: torch.Tensor, classes: torch.Tensor, gt: dict, max_dist: float = 1.5
) -> torch.Tensor:
    """The GT instance id of each detected instance, -1 for none: one-to-one (Hungarian) on the
    symmetric Chamfer distance within each class, kept below ``max_dist`` metres.

    points (N, P, 2) ego metres, classes (N,), gt a ``prepare_gt`` dict -> (N,) int64.
    """
    from scipy.optimize import linear_sum_assignment

    n, g = points.shape[0], gt["ids"].shape[0]
    ids = torch.full((n,), -1, dtype=torch.int64)
    if n == 0 or g == 0:
        return ids
    a = points.float().cpu()[:, None, :, None]  # (N, 1, P, 1, 2)
    b = gt["points"].float().cpu()[None, :, None]  # (1, G, 1, P, 2)
    dist = (a - b).norm(dim=-1)  # (N, G, P, P)
    chamfer = 0.5 * (dist.min(dim=-1).values.mean(-1) + dist.min(dim=-2).values.mean(-1))
    chamfer = chamfer.masked_fill(classes.cpu()[:, None] != gt["classes"].cpu()[None], 1e6)
    rows, cols = linear_sum_assignment(chamfer.numpy())
    for r, c in zip(rows.tolist(), cols.tolist(), strict=True):
        if chamfer[r, c] <= max_dist:
            ids[r] = gt["ids"].cpu()[c]
    return ids


class SegAssociationObjective(nn.Module):
    """forward(batch of cached BEVs) -> {'loss', 'asso', 'pairs'}: the association head trained
    on the instances of the segmentation head (``model.instances = "segmentation"``), the rest
    frozen. Per sample and frame t > 0: the instances of frames t and t-1 (``segment_instances``)
    get the ids of the GT they lie on (``gt_ids_of``); the previous frame's instances, moved into
    the current frame, are the tracks; the loss is L_asso (BCE against the GT match matrix)."""

    def __init__(self, net: ICMapperNet, cfg: TrainConfig) -> None:
        super().__init__()
        self.detector = net.detector
        self.association = net.association
        self.detector.requires_grad_(False)

    def train(self, mode: bool = True) -> SegAssociationObjective:
        super().train(mode)
        self.detector.eval()
        return self

    def forward(self, batch: dict) -> dict[str, torch.Tensor]:
        check_batch(batch)
        if batch["images"] is not None:
            raise ValueError("the segmentation association trains on cached BEVs (freeze_encoder)")
        det = self.detector
        bev = batch["bev"]  # (B, T, C, X, Y)
        dev = bev.device
        total = bev.new_zeros(())
        n_terms, n_pairs = 0, 0
        for b in range(bev.shape[0]):
            prev = None
            for t in range(bev.shape[1]):
                inst, q = det.segment_instances(bev[b : b + 1, t])  # (N, C)
                pts = torch.as_tensor(inst.points, device=dev)  # (N, P, 2) metres
                gt = prepare_gt(batch["gt"][b][t], det, dev)
                ids = gt_ids_of(pts, torch.as_tensor(inst.classes), gt).to(dev)
                if prev is not None and len(inst) and prev[0].shape[0]:
                    motion = prev_to_cur(batch["poses"][b : b + 1], t)  # (1, 4, 4)
                    p_trk = transform_points(prev[1][None], motion)[0]  # (T, P, 2) metres
                    logits = self.association(
                        q[None], det.to_unit(pts)[None], prev[0][None], det.to_unit(p_trk)[None]
                    )[0]  # (D, T)
                    target = association_targets(ids, prev[2])
                    total = total + association_loss(logits, target)
                    n_terms += 1
                    n_pairs += int(target.sum())
                prev = (q, pts, ids)
        l_asso = total / max(1, n_terms)
        return {"loss": l_asso, "asso": l_asso, "pairs": torch.tensor(float(n_pairs))}


class Stage2Objective(nn.Module):
    """forward(batch) -> {'loss', 'fusion', 'fused'}: per sample, frames in order; detections
    above the score threshold are matched to the GT (their IDs are the GT IDs: oracle identities
    for training), fused with the history of the same ID sampled from the online global map, and the
    fused points (detached) merged into the map (crossings by the ``[mapper]`` table's
    ``crossing_merge``, fused polylines by its ``fused_merge``, the passed stretch left alone by
    its ``merge_behind``, as at inference)."""

    def __init__(
        self, net: ICMapperNet, cfg: TrainConfig, map_factory: Callable[[], Any] | None = None
    ) -> None:
        super().__init__()
        self.detector = net.detector
        self.association = net.association
        self.fusion = net.fusion
        self.map_factory = map_factory  # default: icmapper.GlobalMap (the Rust engine)
        self.merge_failures = 0  # merges skipped on degenerate geometry
        self.criterion = DetectionCriterion(
            cfg.model.num_classes, cfg.stage1.cls_weight, cfg.stage1.pts_weight
        )
        self.cfg = cfg
        # the online map merges crossings by the rule the mapper will use (the [mapper] table)
        mapper_cfg = MapperConfig.from_dict(cfg.mapper)
        self.crossing_merge = mapper_cfg.crossing_merge
        self.fused_merge, self.splice_overlap = mapper_cfg.fused_merge, mapper_cfg.splice_overlap
        self.merge_behind = mapper_cfg.merge_behind
        for mod in (self.detector, self.association):
            mod.requires_grad_(False)

    def train(self, mode: bool = True) -> Stage2Objective:
        super().train(mode)
        self.detector.eval()  # frozen: BatchNorm statistics stay fixed
        self.association.eval()
        return self

    @torch.no_grad()
    def detect(self, batch: dict) -> list[DetectorOutput]:
        """The frozen detector over the clip: one DetectorOutput per frame (from the cached
        BEVs where the batch has them: ``stage2.cached_bev``); with segmentation instances it
        holds the BEV alone (no decoder queries)."""
        cached = batch["images"] is None
        det = self.detector
        # segmentation instances need the BEV alone: the set decoder is skipped, as at inference
        bev_only = det.cfg.instances == "segmentation"
        outs, state = [], None
        for t in range(batch["poses"].shape[1]):
            motion = prev_to_cur(batch["poses"], t) if t > 0 else None
            if bev_only:
                if cached:
                    bev = batch["bev"][:, t]  # (B, C, X, Y)
                else:
                    bev, state = det.encode_stream(*frame_cameras(batch, t), state, motion)
                out = DetectorOutput([], [], bev.new_zeros((bev.shape[0], 0, bev.shape[1])), bev)
            elif cached:
                out, state = det.decode(batch["bev"][:, t], state, motion)
            else:
                out, state = det(*frame_cameras(batch, t), state, motion)
            outs.append(out)
        return outs

    def matched(
        self, out: DetectorOutput, b: int, gt: dict
    ) -> tuple[torch.Tensor, torch.Tensor, list[int]]:
        """Sample b's detections above the score threshold that lie on a GT instance: classes
        (M,), points (M, P, 2) ego metres and their GT ids. Decoder instances are matched as in
        L_det; vectorised segmentation instances (``model.instances``) by ``gt_ids_of``."""
        det, thr = self.detector, self.cfg.stage2.score_threshold
        if det.cfg.instances == "segmentation":
            inst, _ = det.segment_instances(out.bev[b : b + 1])
            dev = out.bev.device
            cls_all = torch.as_tensor(inst.classes, device=dev)  # (N,)
            pts_all = torch.as_tensor(inst.points, device=dev)  # (N, P, 2) metres
            ids_all = gt_ids_of(pts_all, cls_all, gt)  # (N,)
            keep = torch.nonzero((ids_all >= 0) & torch.as_tensor(inst.scores > thr)).flatten()
            return cls_all[keep], pts_all[keep], ids_all[keep].tolist()
        keep = torch.nonzero(out.scores()[b] > thr).flatten()
        if keep.numel() == 0:
            return out.classes()[b, keep], out.points[-1][b, keep], []
        pi, gi, _ = self.criterion.matcher(
            out.logits[-1][b, keep], out.points[-1][b, keep], gt["classes"], gt["points01"]
        )
        slots = keep[pi]  # (M,)
        pts = det.to_metres(out.points[-1][b, slots]).float()  # (M, P, 2)
        return out.classes()[b, slots], pts, gt["ids"][gi].tolist()

    def forward(self, batch: dict) -> dict[str, torch.Tensor]:
        if self.map_factory is None:
            from icmapper import GlobalMap  # the Rust engine

            self.map_factory = GlobalMap
        check_batch(batch)
        cfg, det = self.cfg, self.detector
        dev = batch["poses"].device
        r = cfg.perception_range
        scale = torch.tensor([r.half_x, r.half_y], device=dev)
        outs = self.detect(batch)
        total = sum(p.sum() * 0.0 for p in self.fusion.parameters())
        n_terms, n_fused = 0, 0
        for b in range(batch["poses"].shape[0]):
            gmap = self.map_factory()
            crossings = CrossingMerger(self.crossing_merge, r)
            for t, out in enumerate(outs):
                gt = prepare_gt(batch["gt"][b][t], det, dev)
                pose = batch["poses"][b, t].cpu().numpy().astype(np.float64)
                if gt["ids"].numel() == 0:
                    continue
                cls, pts, ids = self.matched(out, b, gt)  # (M,), (M, P, 2) metres, M ids
                if not ids:
                    continue
                gt_row = {int(i): r for r, i in enumerate(gt["ids"].tolist())}
                gi = torch.tensor([gt_row[i] for i in ids], dtype=torch.int64, device=dev)  # (M,)
                h_ids, _, h_pts, _ = gmap.sample_patch(
                    pose_to_xy_yaw(pose),
                    (r.half_x, r.half_y),
                    margin=cfg.model.fusion_margin,
                    n_points=cfg.model.fusion_history_points,
                )
                row = {int(i): j for j, i in enumerate(np.asarray(h_ids).tolist())}
                has = torch.tensor([i in row for i in ids], dtype=torch.bool, device=dev)
                hist = torch.zeros(len(ids), cfg.model.fusion_history_points, 2, device=dev)
                if has.any():
                    h_pts_t = torch.as_tensor(np.asarray(h_pts), dtype=torch.float32, device=dev)
                    for j, i in enumerate(ids):
                        if i in row:
                            hist[j] = h_pts_t[row[i]]
                fused = self.fusion(pts, cls, hist, has)  # list of (M, P, 2) metres
                if has.any():
                    total = total + fusion_loss(
                        [f[has] for f in fused],
                        gt["points"][gi][has],
                        gt["classes"][gi][has],
                        scale,
                    )
                    n_terms += 1
                    n_fused += int(has.sum())
                final = fused[-1].detach().cpu().numpy().astype(np.float64)  # (M, P, 2)
                for j, i in enumerate(ids):
                    world = ego_to_world(final[j], pose)  # (P, 2)
                    try:
                        crossing = int(cls[j]) == MapClass.PED_CROSSING
                        if i in gmap and crossing:
                            crossings.merge(gmap, i, world, final[j], t)
                        elif i in gmap:  # spliced or fitted, not the passed stretch
                            spliced = bool(has[j]) and self.fused_merge == "splice"
                            overlap = self.splice_overlap if spliced else None
                            merge_view(gmap, i, final[j], world, self.merge_behind, t, overlap)
                        else:
                            gmap.insert_with_id(i, int(cls[j]), world, frame=t)
                            if crossing:
                                crossings.inserted(i, final[j])
                    except ValueError:
                        # degenerate geometry (a collapsed or zig-zag detection): the map keeps
                        # what it had, as the online Mapper does
                        self.merge_failures += 1
        l_fusion = total / max(1, n_terms)
        return {
            "loss": cfg.stage2.lambda_fusion * l_fusion,
            "fusion": l_fusion,
            "fused": torch.tensor(float(n_fused)),
        }
