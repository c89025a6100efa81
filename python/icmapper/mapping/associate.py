"""The association scores of one frame: detections against the tracking buffer (step 2 of the
mapper's pipeline, before the tracker's one-to-one assignment).

Learned scores ``H`` of the association head when both sides carry query features, positional
affinity otherwise (with what each pair shares, ``tracker.overlap``, for the assignment to weigh
the pairs by). Scores only: the assignment and the buffer are the tracker's (``mapping.tracker``).
No I/O.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from icmapper.mapping.tracker import (
    affinity_of,
    check_positional,
    same_class_distances,
    shared_of,
)
from icmapper.mapping.types import Detections

if TYPE_CHECKING:
    import torch

    from icmapper.models.association import AssociationHead


def association_scores(
    det: Detections,
    trk_cls: NDArray[np.int64],
    trk_pts: NDArray[Any],
    trk_q: NDArray[np.float32] | None,
    *,
    head: AssociationHead | None,
    to_unit: Callable[[torch.Tensor], torch.Tensor] | None,
    device: str | torch.device,
    positional_scale: float,
    share_gate: float = 0.0,
) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    """Scores (k, t) of the k detections against the t tracks (classes (t,), points (t, P, 2)
    ego, queries (t, D) or None), and what each pair shares (k, t) where the scores are
    positional and ``share_gate`` > 0 (``tracker.overlap`` at that gate; else None). ``head``
    (None: positional affinity) scores the pairs when the detections and the tracks carry
    queries; ``to_unit`` maps metres to the head's unit frame."""
    k, t = len(det), len(trk_cls)
    if k == 0 or t == 0:
        return np.zeros((k, t), np.float64), None
    if head is not None and det.queries is not None and trk_q is not None:
        import torch

        if to_unit is None:
            raise TypeError("learned association needs the detector's to_unit (metres -> unit)")

        with torch.no_grad():
            s = head.scores(
                torch.as_tensor(det.queries, device=device),
                to_unit(torch.as_tensor(det.points, device=device)),
                torch.as_tensor(trk_q, device=device),
                to_unit(torch.as_tensor(trk_pts, device=device)),
            )  # (k, t)
        return s.cpu().numpy().astype(np.float64), None
    check_positional(positional_scale, "min")
    aff = np.zeros((k, t), np.float64)  # tracker.positional_affinity, reduce "min": instances
    # grow and shrink at the range edge
    shared = np.zeros((k, t), np.float64) if share_gate > 0 else None  # tracker.overlap
    for di, ti, ab, ba in same_class_distances(det.points, det.classes, trk_pts, trk_cls):
        aff[np.ix_(di, ti)] = affinity_of(ab, ba, positional_scale, "min")
        if shared is not None:
            shared[np.ix_(di, ti)] = shared_of(ab, ba, share_gate)
    return aff, shared
