"""The learned detector as a streaming ``DetectionSource`` of the mapper: it keeps the BEV memory
and the propagated queries from one frame to the next, and saves / restores them as plain numpy
arrays (for ``Mapper.save_state``)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from icmapper.data.types import Frame
from icmapper.mapping.types import Detections

if TYPE_CHECKING:
    import torch

    from icmapper.models.detector import MapDetector


class NetworkDetector:
    """The learned detector as a streaming ``DetectionSource`` (memory carried between frames).

    With ``model.instances = "segmentation"`` only the encoder runs (``encode_stream``): the
    instances are the vectorised masks of the BEV, and the memory is the BEV alone.

    ``temporal=False`` gives the single-frame variant (no BEV memory, no query propagation).
    """

    def __init__(
        self, detector: MapDetector, device: str | torch.device = "cpu", temporal: bool = True
    ):
        import torch

        self.detector = detector.eval().to(device)
        self.device = torch.device(device)
        self.temporal = temporal
        self.reset()

    def reset(self) -> None:
        self._state: Any = None
        self._prev_pose: NDArray[np.float64] | None = None

    def state_dict(self) -> dict[str, NDArray[Any]]:
        """The streaming memory as numpy arrays (for ``Mapper.save_state``; no tensors, no pickle).

        Keys: ``has_state`` () bool; when true also ``bev`` (1, C, X, Y) float32, ``queries``
        (1, k, C) float32, ``points`` (1, k, P, 2) float32 in [0, 1], ``src_index`` (1, k) int64
        (the ``DetectorState``; k = 0 in segmentation mode) and ``prev_pose`` (4, 4) float64
        ego->world of the last frame.
        """
        if self._state is None or self._prev_pose is None:
            return {"has_state": np.array(False)}
        st = self._state
        return {
            "has_state": np.array(True),
            "bev": st.bev.detach().cpu().numpy(),  # (1, C, X, Y)
            "queries": st.queries.detach().cpu().numpy(),  # (1, k, C)
            "points": st.points.detach().cpu().numpy(),  # (1, k, P, 2)
            "src_index": st.src_index.detach().cpu().numpy(),  # (1, k)
            "prev_pose": np.asarray(self._prev_pose, np.float64).copy(),  # (4, 4)
        }

    def load_state_dict(self, state: dict[str, NDArray[Any]]) -> None:
        """Restores the memory written by ``state_dict`` (ValueError on missing keys, wrong
        shapes or dtypes; nothing changes then)."""
        import torch

        from icmapper.models.detector import DetectorState

        if "has_state" not in state or np.asarray(state["has_state"]).shape != ():
            raise ValueError("detector state: missing or malformed 'has_state'")
        if not bool(state["has_state"]):
            self.reset()
            return
        missing = {"bev", "queries", "points", "src_index", "prev_pose"} - set(state)
        if missing:
            raise ValueError(f"detector state: missing arrays {sorted(missing)}")
        model = self.detector.cfg
        bev, q, pts = state["bev"], state["queries"], state["points"]
        idx, pose = state["src_index"], state["prev_pose"]
        k = q.shape[1] if q.ndim == 3 else -1
        checks = [
            ("bev", bev, bev.ndim == 4 and bev.shape[:2] == (1, model.channels), np.float32),
            ("queries", q, q.shape == (1, k, model.channels), np.float32),
            ("points", pts, pts.shape == (1, k, model.num_points, 2), np.float32),
            ("src_index", idx, idx.shape == (1, k), np.int64),
            ("prev_pose", pose, pose.shape == (4, 4), np.float64),
        ]
        for name, arr, ok, dtype in checks:
            if not ok or arr.dtype != dtype:
                raise ValueError(
                    f"detector state: {name} has shape {arr.shape} dtype {arr.dtype}, which does "
                    f"not fit the detector (channels {model.channels}, points {model.num_points})"
                )
            if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
                raise ValueError(f"detector state: {name} contains NaN or inf")
        if k > model.num_queries or (
            idx.size and (idx.min() < 0 or idx.max() >= model.num_queries)
        ):
            raise ValueError("detector state: src_index out of range of the detector's queries")
        dev = self.device
        self._state = DetectorState(
            torch.from_numpy(bev.copy()).to(dev),  # (1, C, X, Y)
            torch.from_numpy(q.copy()).to(dev),  # (1, k, C)
            torch.from_numpy(pts.copy()).to(dev),  # (1, k, P, 2)
            torch.from_numpy(idx.copy()).to(dev),  # (1, k)
        )
        self._prev_pose = pose.astype(np.float64, copy=True)

    def detect(self, frame: Frame) -> Detections:
        import torch

        if frame.images is None:
            raise ValueError(f"frame {frame.index} has no images: the learned detector needs them")
        imgs = np.asarray(frame.images)
        rig = frame.rig
        if imgs.ndim != 4 or imgs.shape[0] != rig.num_cameras or imgs.shape[1] != 3:
            raise ValueError(
                f"frame {frame.index}: images must be ({rig.num_cameras}, 3, H, W), "
                f"got {imgs.shape}"
            )
        pose = np.asarray(frame.pose, dtype=np.float64)
        dev = self.device
        with torch.no_grad():
            images = torch.as_tensor(imgs, device=dev)[None]  # (1, C, 3, H, W)
            intr = torch.as_tensor(rig.intrinsics, dtype=torch.float32, device=dev)[None]
            c2e = torch.as_tensor(rig.cam_to_ego, dtype=torch.float32, device=dev)[None]
            state, motion = None, None
            if self.temporal and self._state is not None and self._prev_pose is not None:
                m = np.linalg.inv(pose) @ self._prev_pose  # (4, 4) previous ego -> current ego
                motion = torch.as_tensor(m, dtype=torch.float32, device=dev)[None]
                state = self._state
            if self.detector.cfg.instances == "segmentation":  # the set decoder is not needed
                bev, new_state = self.detector.encode_stream(images, intr, c2e, state, motion)
                inst, queries = self.detector.segment_instances(bev)  # (N, C)
                scores = torch.as_tensor(inst.scores, device=dev)  # (N,)
                classes = torch.as_tensor(inst.classes, device=dev)  # (N,)
                points = torch.as_tensor(inst.points, device=dev)  # (N, P, 2) ego metres
            else:
                out, new_state = self.detector(images, intr, c2e, state, motion)
                scores = out.scores()[0]  # (Q,)
                classes = out.classes()[0]  # (Q,)
                points = self.detector.to_metres(out.points[-1][0])  # (Q, P, 2) ego metres
                queries = out.queries[0]  # (Q, C)
        if self.temporal:
            self._state, self._prev_pose = new_state, pose
        order = torch.argsort(scores, descending=True, stable=True)
        return Detections(
            classes=classes[order].cpu().numpy().astype(np.int64),
            scores=scores[order].cpu().numpy().astype(np.float32),
            points=points[order].cpu().numpy().astype(np.float32),
            queries=queries[order].cpu().numpy().astype(np.float32),
        )
