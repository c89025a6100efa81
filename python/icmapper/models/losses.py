"""Losses of IC-Mapper (paper Eq. 1-2, 4, 13): detection (focal + SmoothL1 on the best point order,
on every decoder layer), query transfer (L1), association (BCE against the GT match matrix) and
fusion (SmoothL1 on the best order). Points are compared in [0, 1] units of the perception range.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn

from icmapper.models.matcher import HungarianMatcher, expand_point_orders


def sigmoid_focal_loss(
    logits: torch.Tensor, targets: torch.Tensor, alpha: float = 0.25, gamma: float = 2.0
) -> torch.Tensor:
    """Summed focal loss; logits and one-hot targets (..., K)."""
    logits = logits.float()
    p = logits.sigmoid()
    ce = F.binary_cross_entropy_with_logits(logits, targets, reduction="none")
    p_t = p * targets + (1 - p) * (1 - targets)
    loss = ce * (1 - p_t) ** gamma
    loss = (alpha * targets + (1 - alpha) * (1 - targets)) * loss
    return loss.sum()


def best_order(pred: torch.Tensor, gt: torch.Tensor, classes: torch.Tensor) -> torch.Tensor:
    """The equivalent point order of each GT closest (L1) to its prediction.

    pred (M, P, 2), gt (M, P, 2), classes (M,) -> (M, P, 2) reordered GT.
    """
    orders, valid = expand_point_orders(gt, classes)  # (M, O, P, 2), (M, O)
    d = (pred.detach()[:, None].float() - orders).abs().mean(dim=(-1, -2))  # (M, O)
    d = d.masked_fill(~valid, float("inf"))
    idx = d.argmin(dim=1)  # (M,)
    return orders[torch.arange(gt.shape[0], device=gt.device), idx]  # (M, P, 2)


@dataclass
class FrameMatch:
    """Last-layer match of one sample: pred_idx (M,), gt_idx (M,), gt_ids (M,) instance ids."""

    pred_idx: torch.Tensor
    gt_idx: torch.Tensor
    gt_ids: torch.Tensor


class DetectionCriterion(nn.Module):
    """L_det over all decoder layers for one frame of a batch.

    forward(logits list of (B, Q, K), points list of (B, Q, P, 2) in [0, 1], gts: list (B) of dicts
    with 'classes' (G,), 'points01' (G, P, 2), 'ids' (G,)) -> (loss scalar, per-sample FrameMatch
    of the last layer).
    """

    def __init__(
        self,
        num_classes: int = 3,
        cls_weight: float = 2.0,
        pts_weight: float = 5.0,
        alpha: float = 0.25,
        gamma: float = 2.0,
    ) -> None:
        super().__init__()
        self.num_classes = num_classes
        self.cls_weight, self.pts_weight = cls_weight, pts_weight
        self.alpha, self.gamma = alpha, gamma
        self.matcher = HungarianMatcher(cls_weight, pts_weight)

    def forward(
        self, logits: list[torch.Tensor], points: list[torch.Tensor], gts: list[dict]
    ) -> tuple[torch.Tensor, list[FrameMatch]]:
        total = logits[0].new_zeros((), dtype=torch.float32)
        num_gt = max(1, sum(int(g["classes"].numel()) for g in gts))
        matches: list[FrameMatch] = []
        for layer, (lg, pt) in enumerate(zip(logits, points, strict=True)):
            for b, g in enumerate(gts):
                pi, gi, _ = self.matcher(lg[b], pt[b], g["classes"], g["points01"])
                target = torch.zeros_like(lg[b], dtype=torch.float32)  # (Q, K)
                target[pi, g["classes"][gi]] = 1.0
                cls = sigmoid_focal_loss(lg[b], target, self.alpha, self.gamma)
                total = total + self.cls_weight * cls / num_gt
                if pi.numel():
                    pred = pt[b][pi].float()  # (M, P, 2)
                    tgt = best_order(pred, g["points01"][gi], g["classes"][gi])  # (M, P, 2)
                    reg = F.smooth_l1_loss(pred, tgt, beta=0.01, reduction="sum") / pred.shape[1]
                    total = total + self.pts_weight * reg / num_gt
                if layer == len(logits) - 1:
                    matches.append(FrameMatch(pi, gi, g["ids"][gi]))
        return total / len(logits), matches


def repeat_targets(gt: dict, repeats: int) -> dict:
    """The targets of one-to-many matching: every GT instance ``repeats`` times (classes,
    points01 and ids repeated, instance order kept within each copy), so that the Hungarian
    matcher assigns up to ``repeats`` queries to each instance (MapTRv2's hybrid matching)."""
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    return {
        "classes": gt["classes"].repeat(repeats),  # (R*G,)
        "points01": gt["points01"].repeat(repeats, 1, 1),  # (R*G, P, 2)
        "ids": gt["ids"].repeat(repeats),  # (R*G,)
    }


def trans_loss(
    trans_points: torch.Tensor,
    prop_src: torch.Tensor,
    prev_matches: list[FrameMatch],
    gts: list[dict],
) -> torch.Tensor:
    """L_trans: L1 between the points regressed from the propagated queries and the same instances'
    GT points in the current frame (best order).

    trans_points (B, k, P, 2) [0, 1]; prop_src (B, k) query slots of the previous frame;
    prev_matches the previous frame's FrameMatch per sample; gts the current frame's GT.
    Returns the mean over pairs that exist in both frames (0 when none).
    """
    preds, tgts, clss = [], [], []
    for b, g in enumerate(gts):
        slot_to_id = dict(
            zip(prev_matches[b].pred_idx.tolist(), prev_matches[b].gt_ids.tolist(), strict=True)
        )
        id_to_gt = {int(i): j for j, i in enumerate(g["ids"].tolist())}
        for j, slot in enumerate(prop_src[b].tolist()):
            gid = slot_to_id.get(slot)
            if gid is not None and gid in id_to_gt:
                preds.append(trans_points[b, j])
                tgts.append(g["points01"][id_to_gt[gid]])
                clss.append(g["classes"][id_to_gt[gid]])
    if not preds:
        return trans_points.sum() * 0.0
    pred = torch.stack(preds).float()  # (M, P, 2)
    tgt = best_order(pred, torch.stack(tgts), torch.stack(clss))  # (M, P, 2)
    return F.l1_loss(pred, tgt)


def association_targets(det_ids: torch.Tensor, trk_ids: torch.Tensor) -> torch.Tensor:
    """GT match matrix (Eq. 4): det_ids (D,), trk_ids (T,) with -1 = no instance -> (D, T) float,
    1 where both carry the same instance id."""
    same = det_ids[:, None] == trk_ids[None, :]  # (D, T)
    known = (det_ids[:, None] >= 0) & (trk_ids[None, :] >= 0)
    return (same & known).float()


def association_loss(logits: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
    """L_asso: BCE with logits, mean over pairs; logits/targets (D, T)."""
    if logits.numel() == 0:
        return logits.sum() * 0.0
    return F.binary_cross_entropy_with_logits(logits.float(), targets)


def fusion_loss(
    layer_points: list[torch.Tensor], gt: torch.Tensor, classes: torch.Tensor, scale: torch.Tensor
) -> torch.Tensor:
    """L_fusion: SmoothL1 of every fusion layer's points to the GT (best order), in units of
    ``scale`` (2,) metres. layer_points: list of (N, P, 2) metres; gt (N, P, 2) metres."""
    if gt.shape[0] == 0:
        return layer_points[0].sum() * 0.0
    tgt = best_order(layer_points[-1] / scale, gt / scale, classes)  # (N, P, 2)
    loss = sum(F.smooth_l1_loss(p / scale, tgt, beta=0.01) for p in layer_points)
    return loss / len(layer_points)
