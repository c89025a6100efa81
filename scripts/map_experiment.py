"""Mapping experiments on the learned detector's BEVs, cached: the clean-maps issue's tool.

Runs the learned detector's encoder once per frame and caches each frame's BEV (``--cache``), so
later runs vary the vectoriser (``--vec NAME=VALUE``, ``models.vectorise.VectoriseParams``) and
the mapping settings (``--set NAME=VALUE``, ``MapperConfig``) without rendering or encoding again.
Every method maps the same detections (IC-Mapper's, recorded, replayed to the baselines, as
``icmapper compare`` does). Prints, per method, the map error, mGAP, ID switches and the
map's cleanliness (``eval.fragmentation``); ``--directions`` the two halves of each class's CD
(the map's points to the ground truth, the ground truth's to the map), the stray instances'
part, what the mapping lost of what the detections saw, and the floor the detections set on
the CD (``coverage_floor``); ``--reestimate GATE`` adds each method's map with its lines redrawn
from every view that drew them (``reestimate``); ``--json`` writes them.

    .venv/bin/python scripts/map_experiment.py --source sim:val:4 \
        --methods icmapper,post-track,polymerge --set map_nms=true

A cached BEV belongs to its encoder (the digest of its parameters) and source: a retrained
encoder gets its own, a checkpoint whose fusion or association alone changed shares it.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import sys
import time
from dataclasses import fields, replace
from pathlib import Path
from typing import Any

import numpy as np


def _parse_sets(items: list[str], cls: type) -> dict[str, Any]:
    table: dict[str, Any] = {}
    for it in items:
        k, _, v = it.partition("=")
        table[k] = json.loads(v) if v not in ("true", "false") else v == "true"
    names = {f.name for f in fields(cls)}
    bad = set(table) - names
    if bad:
        raise SystemExit(f"unknown {cls.__name__} settings {sorted(bad)}")
    return table


def bev_cache_dir(
    root: str, detector: Any, image_size: tuple[int, int], source: str, hz: float | None = None
) -> Path:
    """The folder of ``CachedBev``'s encoder outputs for one encoder (its parameters' digest,
    ``training.bevcache.encoder_digest``: checkpoints that differ only after the BEV, such as a
    retrained fusion, share it) and source (and keyframe rate, when not the source's own)."""
    from icmapper.training.bevcache import encoder_digest

    encoder = encoder_digest(detector, image_size)
    rate = f"|{hz}" if hz is not None else ""
    return Path(root) / hashlib.sha1(f"{encoder}|{source}{rate}".encode()).hexdigest()[:10]


class CachedBev:
    """The learned detector as a ``DetectionSource`` whose encoder output is cached per frame."""

    def __init__(self, inner: Any, cache: Path, vec: Any) -> None:
        self.inner = inner
        self.detector = inner.detector
        self.cache = cache
        self.vec = vec
        self.bevs: dict[int, np.ndarray] = {}

    def reset(self) -> None:
        self.inner.reset()

    def load(self, name: str) -> bool:
        path = self.cache / f"{name}.npz"
        self.bevs = dict(np.load(path)) if path.exists() else {}
        self.bevs = {int(k): v for k, v in self.bevs.items()}
        return bool(self.bevs)

    def save(self, name: str) -> None:
        self.cache.mkdir(parents=True, exist_ok=True)
        tmp = self.cache / f".{name}.tmp.npz"
        np.savez(tmp, **{str(k): v for k, v in self.bevs.items()})
        os.replace(tmp, self.cache / f"{name}.npz")

    def detect(self, frame: Any) -> Any:
        import torch
        from icmapper.mapping.types import Detections

        if frame.index not in self.bevs:
            inner = self.inner
            det = inner.detector
            imgs = torch.as_tensor(np.asarray(frame.images))[None]
            rig = frame.rig
            intr = torch.as_tensor(rig.intrinsics, dtype=torch.float32)[None]
            c2e = torch.as_tensor(rig.cam_to_ego, dtype=torch.float32)[None]
            pose = np.asarray(frame.pose, np.float64)
            state = motion = None
            if inner._state is not None:
                m = np.linalg.inv(pose) @ inner._prev_pose
                motion = torch.as_tensor(m, dtype=torch.float32)[None]
                state = inner._state
            with torch.no_grad():
                bev, inner._state = det.encode_stream(imgs, intr, c2e, state, motion)
            inner._prev_pose = pose
            self.bevs[frame.index] = bev.numpy()
        bev_t = torch.from_numpy(self.bevs[frame.index])
        with torch.no_grad():
            inst, queries = self.detector.segment_instances(bev_t, self.vec)
        order = np.argsort(-inst.scores, kind="stable")
        return Detections(
            classes=inst.classes[order].astype(np.int64),
            scores=inst.scores[order].astype(np.float32),
            points=inst.points[order].astype(np.float32),
            queries=queries.numpy()[order].astype(np.float32),
        )


def main(argv: list[str] | None = None) -> int:
    from icmapper.checkpoints import DEFAULT_CHECKPOINT
    from icmapper.data import gt as gt_mod
    from icmapper.data.sources import open_source
    from icmapper.eval.evaluate import evaluate
    from icmapper.mapping.config import MapperConfig
    from icmapper.mapping.mapper import Mapper
    from icmapper.mapping.methods import method
    from icmapper.mapping.run import RecordingSource, ReplaySource, map_sequence
    from icmapper.models.vectorise import VectoriseParams

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--source", required=True)
    ap.add_argument("--methods", default="icmapper,post-track,polymerge")
    ap.add_argument("--checkpoint", default=str(DEFAULT_CHECKPOINT))
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    ap.add_argument("--vec", action="append", default=[], metavar="NAME=VALUE")
    ap.add_argument("--cache", default="/tmp/icmapper-bev-cache")
    ap.add_argument("--json", default=None)
    ap.add_argument(
        "--gt-join-gap",
        type=float,
        default=0.0,
        help="what-if: the global ground truth joins the visited pieces of a line less than this "
        "many metres apart along it (data.gt.global_gt; 0: the protocol)",
    )
    ap.add_argument("--maps", default=None, help="folder for each method's .icmap per drive")
    ap.add_argument(
        "--min-obs", type=int, default=1, help="leave out map instances observed fewer times"
    )
    ap.add_argument(
        "--directions",
        action="store_true",
        help="also the two halves of each class's CD (precision, coverage) and the strays",
    )
    ap.add_argument(
        "--reestimate",
        type=float,
        default=0.0,
        metavar="GATE",
        help="what-if: also each method's map with every finished lane line and kerb point moved "
        "to the mean of the nearest points of the tracked detections within GATE metres of it "
        "(one per detection: every view that drew it), to tell noise between views from error "
        "they share (0: off)",
    )
    ap.add_argument(
        "--stop",
        type=int,
        default=0,
        help="what-if: each drive stops for this many frames halfway (its middle frame held: "
        "the same pose and images; synthetic drives never stop; 'MapperConfig.min_travel')",
    )
    ap.add_argument(
        "--stop-at", type=int, default=None, help="the frame --stop holds (default: the middle)"
    )
    ap.add_argument(
        "--hz",
        type=float,
        default=None,
        help="what-if: synthetic drives sampled at this many keyframes per second (the same "
        "routes; the sources' rate is data.types.KEYFRAME_HZ, 2)",
    )
    a = ap.parse_args(argv)
    if not (np.isfinite(a.reestimate) and a.reestimate >= 0):
        ap.error(f"--reestimate must be a finite distance >= 0, got {a.reestimate}")
    names = a.methods.split(",")
    for n in names:  # before any work: a misspelt method would fail only after recording
        try:
            method(n)
        except ValueError as e:
            ap.error(f"--methods: {e}")

    vec = replace(VectoriseParams(), **_parse_sets(a.vec, VectoriseParams))
    from icmapper.models.network import checkpoint_settings

    if a.hz is not None:  # the synthetic driver's keyframe rate, for this run only
        from functools import partial

        import icmapper.data.sim.sequences as sim_sequences
        from icmapper.data.sim.driver import drive

        sim_sequences.drive = partial(drive, hz=a.hz)  # type: ignore[assignment]
    image_size = checkpoint_settings(a.checkpoint)[1]
    seqs = open_source(a.source, image_size=image_size)
    if a.stop:
        seqs = [with_stop(s, a.stop, a.stop_at) for s in seqs]
    mapper = Mapper.from_checkpoint(a.checkpoint)
    cache = bev_cache_dir(a.cache, mapper.source.detector, image_size, a.source, a.hz)
    cfg = MapperConfig.from_dict(_parse_sets(a.set, MapperConfig), mapper.config)
    mapper = Mapper.from_checkpoint(a.checkpoint, config=cfg)
    rng = mapper.rng
    src = CachedBev(mapper.source, cache, vec)
    preds: dict[str, list] = {n: [] for n in names}
    maps: dict[str, list] = {n: [] for n in names}
    gts, ggts = [], []
    seen: list[list[tuple[int, np.ndarray]]] = []  # per drive: (class, points world) tracked
    t0 = time.time()
    for seq in seqs:
        cached = src.load(seq.name)
        rec = RecordingSource(src)
        mapper.source = rec
        if "icmapper" not in names:  # the detections the other methods replay, recorded alone
            rec.reset()
            for i in range(len(seq)):
                rec.detect(seq.frame(i, with_images=not cached))
        for n in sorted(names, key=lambda n: n != "icmapper"):  # the full mapper records them
            if n.startswith("icmapper"):
                variant = "full" if n == "icmapper" else n[len("icmapper-") :]
                m = (
                    mapper
                    if variant == "full"
                    else Mapper.from_checkpoint(a.checkpoint, config=cfg, variant=variant)
                )
                if variant != "full":
                    m.source = ReplaySource(rec.records) if variant == "base" else rec
                frames, gmap = map_sequence(m, seq, with_images=not cached)
            else:
                b = method(n).build(ReplaySource(rec.records), cfg, rng)
                frames, gmap = map_sequence(b, seq, with_images=False)
            preds[n].append(frames)
            items = []
            for i in gmap.ids():
                cls, pts = gmap.get(int(i))
                obs = gmap.info(int(i)).get("observations", 1)
                if obs < a.min_obs:
                    continue
                items.append((int(cls), np.asarray(pts), int(cls) == 0, float(obs or 1)))
            maps[n].append(items)
            if a.maps:
                d = Path(a.maps) / n
                d.mkdir(parents=True, exist_ok=True)
                gmap.save(str(d / f"{seq.name}.icmap"))
        if a.directions or a.reestimate:  # what the detections saw
            seen.append(tracked_world(rec.records, seq.poses, cfg.track_threshold))
        if not cached:
            src.save(seq.name)
        gts.append(gt_mod.sequence_gt(seq, rng))
        ggts.append(gt_mod.global_gt(seq, rng, a.gt_join_gap))
        print(f"{seq.name}: {time.time() - t0:.0f} s", file=sys.stderr)
    out = {}
    print(
        "| method | mAP | IDS | CD_ped | CD_div | CD_bound | mCD | mGAP | n ped/div/bound (GT) "
        "| pieces | dup % | stray % | folded % |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    if a.reestimate:  # the what-if rows beside the methods' own
        for n in list(names):
            pairs = zip(maps[n], seen, strict=True)
            what_if = f"{n} (re-estimated)"
            maps[what_if] = [reestimate(items, dets, a.reestimate) for items, dets in pairs]
            preds[what_if] = preds[n]
            names.append(what_if)
    for n in names:
        r = evaluate(preds[n], gts, maps[n], ggts, rng.name)
        out[n] = r
        mp, fr = r["mapping"], r["mapping"]["fragmentation"]
        cn = ["ped_crossing", "divider", "boundary"]
        cnt = "/".join(str(fr["count"][c]["map"]) for c in cn)
        gtc = "/".join(str(fr["count"][c]["gt"]) for c in cn)
        pcs = "/".join(f"{fr['pieces'][c]:.2f}" for c in cn)
        dup = "/".join(f"{100 * fr['duplicates'][c]:.0f}" for c in cn)
        stray = "/".join(f"{100 * fr['stray'][c]:.0f}" for c in cn)
        folded = "/".join(f"{100 * fr['folded'][c]:.0f}" for c in cn[1:])
        ids = r["tracking"]["mean"]["IDS"]
        print(
            f"| {n} | {100 * r['detection']['mAP']:.1f} | {ids:.2f} | "
            + " | ".join(f"{mp['CD'][c]:.3f}" for c in cn)
            + f" | {mp['mCD']:.3f} | {100 * mp['mGAP']:.1f} | {cnt} ({gtc}) | {pcs} | {dup} "
            f"| {stray} | {folded} |"
        )
    if a.directions:
        print(
            "\n| method | to GT ped/div/bound | from GT | to GT without strays | stray points % "
            "| detected, not mapped % div/bound |"
        )
        print("|---|---|---|---|---|---|")
        for n in names:
            d = cd_directions(maps[n], ggts)
            cells = ["/".join(f"{v:.3f}" for v in d[k]) for k in ("to", "from", "kept")]
            stray = "/".join(f"{100 * v:.1f}" for v in d["stray"])
            lost = "/".join(f"{100 * v:.1f}" for v in detected_not_mapped(maps[n], ggts, seen))
            print(f"| {n} | " + " | ".join(cells) + f" | {stray} | {lost} |")
        floor = coverage_floor(ggts, seen)
        print(
            "\nfloor of the CD from the detections (half the ground truth's distance to the "
            "nearest point any tracked detection drew) ped/div/bound: "
            + "/".join(f"{v:.3f}" for v in floor)
            + f", mean {np.mean(floor):.3f}"
        )
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1, default=float))
    return 0


def with_stop(seq: Any, frames: int, at: int | None = None) -> Any:
    """``seq`` with its frame ``at`` (None: the middle one) held for ``frames`` more frames (its
    pose and images repeated; timestamps every 0.5 s), named "<name>-stop<frames>" ("...-at<K>"
    for another frame than the middle)."""
    k = len(seq) // 2 if at is None else min(max(int(at), 0), len(seq) - 1)
    idx = np.r_[np.arange(k + 1), np.full(frames, k), np.arange(k + 1, len(seq))]  # (T + frames,)
    name = f"{seq.name}-stop{frames}" + (f"-at{k}" if at is not None else "")
    held = seq.select(idx, name)
    held.timestamps = np.arange(len(idx)) * 0.5
    return held


def cd_directions(maps: list, ggts: list) -> dict[str, list[float]]:
    """``eval.globalmap.cd_halves`` per class (crossing, divider, boundary), averaged over the
    drives as the CD is: ``to``, ``from``, ``kept`` and ``stray``."""
    from icmapper.eval.globalmap import cd_halves

    per_drive = [
        cd_halves([(k, pts, closed) for k, pts, closed, _ in items],
                  [(int(m.cls), m.points, m.closed) for m in gt])
        for items, gt in zip(maps, ggts, strict=True)
    ]  # fmt: skip
    names = ["ped_crossing", "divider", "boundary"]
    return {
        k: [float(np.nanmean([d[c][k] for d in per_drive])) for c in names]
        for k in ("to", "from", "kept", "stray")
    }


def tracked_world(
    records: dict[int, Any], poses: Any, threshold: float
) -> list[tuple[int, np.ndarray]]:
    """One drive's recorded detections scoring at least ``threshold`` (the ones IC-Mapper
    tracks and maps), each as (class, points (P, 2) world; a crossing's ring not closed)."""
    out = []
    for i, det in records.items():
        pose = np.asarray(poses[i], np.float64)  # (4, 4) ego -> world
        for j in np.flatnonzero(det.scores >= threshold):
            pts = np.asarray(det.points[j], np.float64)  # (P, 2) ego
            out.append((int(det.classes[j]), pts @ pose[:2, :2].T + pose[:2, 3]))
    return out


def coverage_floor(ggts: list, seen: list[list[tuple[int, np.ndarray]]]) -> list[float]:
    """Per class (crossing, divider, boundary): half the mean distance of the ground truth's
    samples to the nearest point of any tracked detection of the drive (sampled as the CD is),
    averaged over the drives as the CD is. The coverage half of the CD of a map holding every
    point the detections drew: a map drawn from them comes no closer to the truths they never
    reached, so no method's CD of that class falls much below it (the precision half adds)."""
    from icmapper.eval.globalmap import sample_distances

    out = []
    for c in (0, 1, 2):
        per_drive = []
        for gt, dets in zip(ggts, seen, strict=True):
            lines = [x for k, x in dets if k == c]
            d = [sample_distances(m.points, lines, c == 0) for m in gt if int(m.cls) == c]
            if d:
                per_drive.append(0.5 * float(np.concatenate(d).mean()))
        out.append(float(np.mean(per_drive)) if per_drive else float("nan"))
    return out


def reestimate(
    items: list, dets: list[tuple[int, np.ndarray]], gate: float
) -> list[tuple[int, np.ndarray, bool, float]]:
    """One drive's map with every point of its open lines moved to the mean of the nearest
    points (on 0.5 m samples) of the tracked detections of its class that come within ``gate``
    of it, one per detection; a point no detection reached stays. Crossings are kept."""
    from icmapper.eval.globalmap import dense_sample
    from scipy.spatial import cKDTree

    trees = {c: [cKDTree(dense_sample(x, False)) for k, x in dets if k == c] for c in (1, 2)}
    out = []
    for k, pts, closed, obs in items:
        if closed or k not in trees or len(pts) < 2:
            out.append((k, pts, closed, obs))
            continue
        acc, hits = np.zeros_like(pts, np.float64), np.zeros(len(pts))
        for tree in trees[k]:
            dist, idx = tree.query(pts)
            near = dist <= gate
            acc[near] += tree.data[idx[near]]
            hits[near] += 1
        moved = np.array(pts, np.float64)
        moved[hits > 0] = acc[hits > 0] / hits[hits > 0, None]
        out.append((k, moved, closed, obs))
    return out


def detected_not_mapped(
    maps: list, ggts: list, seen: list[list[tuple[int, np.ndarray]]], gate: float = 1.0
) -> list[float]:
    """Per line class (divider, boundary): the share of the ground truth's samples (pooled over
    the drives, sampled as the CD is) that a tracked detection of some frame came within
    ``gate`` metres of and the map did not: what the mapping lost of what was seen."""
    from icmapper.eval.globalmap import dense_sample
    from scipy.spatial import cKDTree

    def near(q: np.ndarray, lines: list[np.ndarray]) -> np.ndarray:
        if not lines:
            return np.zeros(len(q), bool)
        pts = np.concatenate([dense_sample(x, False) for x in lines])
        return cKDTree(pts).query(q)[0] <= gate

    out = []
    for c in (1, 2):
        lost = total = 0
        for items, gt, dets in zip(maps, ggts, seen, strict=True):
            truth = [dense_sample(m.points, False) for m in gt if int(m.cls) == c]
            if not truth:
                continue
            q = np.concatenate(truth)  # (n, 2)
            mapped = near(q, [pts for k, pts, _, _ in items if k == c])
            detected = near(q, [pts for k, pts in dets if k == c])
            lost += int((detected & ~mapped).sum())
            total += len(q)
        out.append(lost / total if total else float("nan"))
    return out


if __name__ == "__main__":
    sys.exit(main())
