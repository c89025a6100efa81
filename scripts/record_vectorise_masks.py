"""Records the shipped checkpoint's segmentation probabilities for frames of a source: the masks
on which the engine's vectoriser is checked against the former Python one
(``tests/test_vectorise_engine.py``) and timed (``python -m benchmarks vectorise``).

Each frame's BEV comes from the detector's streaming encoder (the temporal memory runs over every
frame of a drive, as in ``icmapper map``), or from the BEV cache of ``scripts/map_experiment.py``
when it holds the drive (same checkpoint and source); its probabilities are the sigmoid of
``detector.seg(bev)``, float32 (K, X, Y). The output npz holds one array per kept frame under
``"<drive>/<frame>"`` and ``_half`` (the range's half extents, metres).

    .venv/bin/python scripts/record_vectorise_masks.py --source sim:val:12 --every 25 \\
        --also sim-10008-2/43 --out tests/data/vectorise_masks.npz

``--like FILE`` records the frames another recording holds (to renew it after a checkpoint
change).
"""

from __future__ import annotations

import argparse
import hashlib
import os
from pathlib import Path

import numpy as np


def main(argv: list[str] | None = None) -> int:
    from icmapper.checkpoints import DEFAULT_CHECKPOINT

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--source", default="sim:val:12")
    ap.add_argument("--checkpoint", default=str(DEFAULT_CHECKPOINT))
    ap.add_argument("--every", type=int, default=25, help="keep every N-th frame of the source")
    ap.add_argument("--also", nargs="*", default=[], metavar="DRIVE/FRAME")
    ap.add_argument("--like", default=None, help="record the frames of this recording instead")
    ap.add_argument("--cache", default="/tmp/icmapper-bev-cache")
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)

    import torch
    from icmapper.data.sources import open_source
    from icmapper.mapping.mapper import Mapper
    from icmapper.models.network import checkpoint_settings

    torch.set_num_threads(int(os.environ.get("OMP_NUM_THREADS", "1")))
    mapper = Mapper.from_checkpoint(a.checkpoint)
    det = mapper.source.detector
    key = hashlib.sha1(f"{Path(a.checkpoint).resolve()}|{a.source}".encode()).hexdigest()[:10]
    cache = Path(a.cache) / key
    wanted = set(np.load(a.like).files) - {"_half"} if a.like else set(a.also)
    out: dict[str, np.ndarray] = {}
    seen = 0
    for seq in open_source(a.source, image_size=checkpoint_settings(a.checkpoint)[1]):
        cached = cache / f"{seq.name}.npz"
        bevs = {int(k): v for k, v in np.load(cached).items()} if cached.exists() else {}
        state = prev_pose = None
        for i in range(len(seq)):
            name = f"{seq.name}/{i}"
            keep = name in wanted or (a.like is None and seen % a.every == 0)
            seen += 1
            if i not in bevs:  # stream the encoder over every frame (its temporal memory)
                frame = seq.frame(i)
                pose = np.asarray(frame.pose, np.float64)
                motion = None
                if prev_pose is not None:
                    m = np.linalg.inv(pose) @ prev_pose
                    motion = torch.as_tensor(m, dtype=torch.float32)[None]
                with torch.no_grad():
                    bev, state = det.encode_stream(
                        torch.as_tensor(np.asarray(frame.images))[None],
                        torch.as_tensor(frame.rig.intrinsics, dtype=torch.float32)[None],
                        torch.as_tensor(frame.rig.cam_to_ego, dtype=torch.float32)[None],
                        state,
                        motion,
                    )
                prev_pose = pose
                bevs[i] = bev.numpy()
            if keep:
                with torch.no_grad():
                    logits = det.seg(torch.from_numpy(bevs[i]))[0]  # (K, X, Y)
                out[name] = logits.float().sigmoid().numpy().astype(np.float32)
    out["_half"] = np.array([det.rng.half_x, det.rng.half_y])
    np.savez_compressed(a.out, **out)
    print(f"{len(out) - 1} frames -> {a.out} ({Path(a.out).stat().st_size / 1e6:.2f} MB)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
