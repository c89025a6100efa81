"""Which source frame a predicted frame is: tokens and timestamps of a source's frames.

Every frame of a source has one **token** (what a prediction file may name it by):

- nuScenes (``nuscenes:PATH[:split]``): the sample token (read from ``PATH/<version>/scene.json``
  and ``sample.json``: a scene's sample chain, the same order as the loader's frames);
- Argoverse 2 (``av2:PATH``): the frame's timestamp in nanoseconds as a decimal string (as
  StreamMapNet's and MapTracker's AV2 converters name samples); any all-digit token is matched
  as a nanosecond timestamp (within ``TIME_TOLERANCE``);
- every other source (synthetic drives): ``"<sequence name>:<frame index>"``.

A predicted frame may instead (or also) give a **timestamp** in seconds (``Sequence.timestamps``:
nuScenes sample timestamps / 1e6, AV2 nanoseconds / 1e9, synthetic drives from 0 at 2 Hz); with a
``sequence`` name the search stays in that sequence, without one a timestamp must fall in exactly
one sequence. A token and a timestamp that disagree, or a frame that matches no source frame, is
a ``PredictionFileError`` naming the frame.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from icmapper.data.types import Sequence
from icmapper.formats.types import PredictedFrame, PredictionFileError

#: Seconds within which a timestamp names a frame (keyframes are 0.5 s apart).
TIME_TOLERANCE = 5e-4


def _nuscenes_root(spec: str) -> Path | None:
    kind, _, rest = spec.partition(":")
    if kind != "nuscenes":
        return None
    if not Path(rest).is_dir() and ":" in rest:
        rest = rest.rsplit(":", 1)[0]
    return Path(rest)


def _nuscenes_version(root: Path) -> Path:
    if (root / "v1.0-trainval").is_dir():
        return root / "v1.0-trainval"
    found = sorted(d for d in root.glob("v1.0-*") if d.is_dir())
    if len(found) != 1:
        raise PredictionFileError(f"cannot pick a nuScenes version in {root}: found {found}")
    return found[0]


def _table(folder: Path, name: str) -> list[dict]:
    path = folder / f"{name}.json"
    try:
        rows = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise PredictionFileError(f"{path}: cannot read the nuScenes table ({exc})") from None
    if not isinstance(rows, list):
        raise PredictionFileError(f"{path}: not a JSON list")
    return rows


def _yaw_of_quaternion(q: list[float]) -> float:
    w, x, y, z = (float(v) for v in q)
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


@dataclass
class SourceFrames:
    """The frames of a source's sequences by token and timestamp (see the module docstring).

    names[s]: sequence s's name; timestamps[s] (T_s,) seconds; tokens[s][t]: frame t's token;
    lidar_to_ego[s] (T_s, 3, 3) or None: the LIDAR_TOP frame's planar pose in the ego frame
    (nuScenes; filled by ``load_lidar``).
    """

    spec: str
    names: list[str]
    timestamps: list[NDArray[np.float64]]
    tokens: list[list[str]]
    numeric_tokens: bool = False
    lidar_to_ego: list[NDArray[np.float64] | None] = field(default_factory=list)
    _by_token: dict[str, tuple[int, int]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self._by_token = {
            tok: (s, t) for s, toks in enumerate(self.tokens) for t, tok in enumerate(toks)
        }
        if not self.lidar_to_ego:
            self.lidar_to_ego = [None] * len(self.names)

    @staticmethod
    def of(spec: str, sequences: list[Sequence]) -> SourceFrames:
        """The frames of ``sequences`` opened from ``spec``."""
        names = [s.name for s in sequences]
        stamps = [np.asarray(s.timestamps, dtype=np.float64) for s in sequences]
        root = _nuscenes_root(spec)
        if root is not None:
            tokens = _nuscenes_tokens(root, sequences)
            return SourceFrames(spec, names, stamps, tokens)
        if spec.partition(":")[0] == "av2":
            tokens = [[str(round(float(v) * 1e9)) for v in ts] for ts in stamps]
            return SourceFrames(spec, names, stamps, tokens, numeric_tokens=True)
        tokens = [[f"{s.name}:{t}" for t in range(len(s))] for s in sequences]
        return SourceFrames(spec, names, stamps, tokens)

    def index_of(self, name: str) -> int:
        if name not in self.names:
            raise KeyError(name)
        return self.names.index(name)

    def locate(self, f: PredictedFrame, where: str) -> tuple[int, int]:
        """(sequence index, frame index) of a predicted frame; PredictionFileError naming
        ``where`` and the frame when it names no source frame, or names two."""
        seq = None
        if f.sequence is not None:
            if f.sequence not in self.names:
                raise PredictionFileError(
                    f"{where}: {f.name()}: sequence {f.sequence!r} is not in source {self.spec!r}"
                )
            seq = self.names.index(f.sequence)
        hit: tuple[int, int] | None = None
        if f.token is not None:
            hit = self._by_token.get(f.token)
            if hit is None and self.numeric_tokens and f.token.isdigit():
                hit = self._by_time(int(f.token) * 1e-9, seq, f, where)
            if hit is None:
                raise PredictionFileError(
                    f"{where}: {f.name()}: token names no frame of source {self.spec!r}"
                )
        if f.timestamp is not None:
            by_time = self._by_time(f.timestamp, seq if hit is None else hit[0], f, where)
            if by_time is None:
                raise PredictionFileError(
                    f"{where}: {f.name()}: no frame of source {self.spec!r} at that timestamp"
                )
            if hit is not None and hit != by_time:
                raise PredictionFileError(f"{where}: {f.name()}: token and timestamp disagree")
            hit = by_time
        assert hit is not None
        if seq is not None and hit[0] != seq:
            raise PredictionFileError(
                f"{where}: {f.name()}: the token is a frame of sequence {self.names[hit[0]]!r}"
            )
        return hit

    def _by_time(
        self, ts: float, seq: int | None, f: PredictedFrame, where: str
    ) -> tuple[int, int] | None:
        found = []
        for s in range(len(self.names)) if seq is None else [seq]:
            stamps = self.timestamps[s]
            if stamps.size == 0:
                continue
            t = int(np.argmin(np.abs(stamps - ts)))
            if abs(stamps[t] - ts) <= TIME_TOLERANCE:
                found.append((s, t))
        if len(found) > 1:
            names = ", ".join(repr(self.names[s]) for s, _ in found[:4])
            raise PredictionFileError(
                f"{where}: {f.name()}: the timestamp is a frame of several sequences ({names}); "
                "give the frame's 'sequence'"
            )
        return found[0] if found else None

    def load_lidar(self) -> None:
        """Fills ``lidar_to_ego`` from the nuScenes tables (sample_data of LIDAR_TOP keyframes ->
        calibrated_sensor: translation x, y and the rotation's yaw); identity for other sources
        (Argoverse 2's and synthetic sources' lidar frame is the ego frame)."""
        root = _nuscenes_root(self.spec)
        if root is None:
            self.lidar_to_ego = [
                np.repeat(np.eye(3)[None], len(ts), axis=0) for ts in self.timestamps
            ]
            return
        folder = _nuscenes_version(root)
        sensors = {r["token"]: r.get("channel") for r in _table(folder, "sensor")}
        cal = {
            r["token"]: r
            for r in _table(folder, "calibrated_sensor")
            if sensors.get(r.get("sensor_token")) == "LIDAR_TOP"
        }
        by_sample: dict[str, dict] = {}
        for sd in _table(folder, "sample_data"):
            if sd.get("calibrated_sensor_token") in cal and sd.get("is_key_frame", True):
                by_sample[sd["sample_token"]] = cal[sd["calibrated_sensor_token"]]
        out = []
        for s, toks in enumerate(self.tokens):
            mats = np.empty((len(toks), 3, 3))  # (T, 3, 3)
            for t, tok in enumerate(toks):
                c = by_sample.get(tok)
                if c is None:
                    raise PredictionFileError(
                        f"{folder}: sample {tok} of scene {self.names[s]!r} has no LIDAR_TOP "
                        "keyframe: cannot convert lidar-frame predictions"
                    )
                yaw = _yaw_of_quaternion(c["rotation"])
                cy, sy = math.cos(yaw), math.sin(yaw)
                tx, ty = float(c["translation"][0]), float(c["translation"][1])
                mats[t] = [[cy, -sy, tx], [sy, cy, ty], [0.0, 0.0, 1.0]]
            out.append(mats)
        self.lidar_to_ego = list(out)


def _nuscenes_tokens(root: Path, sequences: list[Sequence]) -> list[list[str]]:
    """Sample tokens of every scene (sequence) in chain order; checked against the timestamps."""
    folder = _nuscenes_version(root)
    scenes = {str(r.get("name", r.get("token"))): r for r in _table(folder, "scene")}
    samples = {r["token"]: r for r in _table(folder, "sample") if isinstance(r, dict)}
    out = []
    for seq in sequences:
        scene = scenes.get(seq.name)
        if scene is None:
            raise PredictionFileError(f"{folder}: no scene {seq.name!r}")
        toks, tok = [], scene.get("first_sample_token", "")
        while tok and len(toks) <= len(samples):
            toks.append(tok)
            tok = samples.get(tok, {}).get("next", "")
        stamps = np.array([samples[k]["timestamp"] for k in toks], dtype=np.float64) * 1e-6
        if len(toks) != len(seq) or np.abs(stamps - seq.timestamps).max(initial=0.0) > 1e-6:
            raise PredictionFileError(
                f"{folder}: the samples of scene {seq.name!r} do not match the loaded sequence"
            )
        out.append(toks)
    return out
