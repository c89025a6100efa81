"""Spatial fusion of one frame (step 5 of the mapper's pipeline): every tracked detection whose
instance has a history in the global map is fused with that history by the fusion network; the
others pass through unchanged. No state, no I/O.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from icmapper.mapping.types import Detections

if TYPE_CHECKING:
    import torch

    from icmapper.models.fusion import FusionModule


def fuse_with_history(
    det: Detections,
    targets: list[int],
    hist_row: dict[int, int],
    hist_pts: NDArray[np.float32],
    fusion: FusionModule,
    history_points: int,
    device: str | torch.device,
    classes: tuple[int, ...] | None = None,
) -> tuple[NDArray[np.float32], NDArray[np.bool_]]:
    """The fused points (m, P, 2) ego and which detections were fused (m,).

    targets: the global instance each of the m detections maps into; hist_row: instance id -> row
    of the sampled history ``hist_pts`` (h, S, 2) ego, S = ``history_points``; classes: the
    classes fused (None: all); a detection of another class passes as if it had no history."""
    none = np.zeros(len(det), bool)
    has = np.array([t in hist_row for t in targets], bool)  # (m,)
    if classes is not None:
        has &= np.isin(det.classes, classes)
    if not has.any():
        return det.points.copy(), none
    import torch

    hist = np.zeros((len(det), history_points, 2), np.float32)  # (m, S, 2)
    hist[has] = hist_pts[[hist_row[t] for t, h in zip(targets, has, strict=True) if h]]
    with torch.no_grad():
        out = fusion(
            torch.as_tensor(det.points, device=device),
            torch.as_tensor(det.classes, device=device),
            torch.as_tensor(hist, device=device),
            torch.as_tensor(has, device=device),
        )[-1]  # (m, P, 2) metres
    return out.cpu().numpy().astype(np.float32), has
