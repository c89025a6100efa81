"""``MapperConfig``: every inference setting of every mapping method, with its default, in one
place.

IC-Mapper and each baseline read their settings from the same ``MapperConfig``, so a comparison
runs every method under the settings the user chose (e.g. one curve-fit smoothing for all). The
fields' ``help`` metadata feeds the command line (``icmapper map --set NAME=VALUE``, and one
``--NAME`` flag for each of ``CLI_FLAGS``); a run folder records the config it ran with
(``mapper_config.json``).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any

from icmapper.data.types import NUM_CLASSES
from icmapper.mapping.crossings import CROSSING_MERGES
from icmapper.mapping.splice import FUSED_MERGES
from icmapper.settings import from_table, to_plain


def _f(default: Any, help: str) -> Any:  # noqa: A002 - argparse's word
    return field(default=default, metadata={"help": help})


@dataclass(frozen=True)
class MapperConfig:
    """Inference settings of the mapping methods (validated on construction: ValueError naming
    the field). Groups: shared by every method; IC-Mapper's; the baselines'."""

    # ---- every method: the global map and the tracking buffer
    smoothing: float = _f(0.5, "curve-fit smoothing s of the merge (scipy splprep semantics)")
    spacing: float = _f(1.0, "metres between stored map points")
    max_age: int = _f(3, "frames a lost track stays in the tracking buffer")
    crossing_merge: str = _f(
        "average",
        "how an observed crossing merges into its instance: 'average' (complete views: running "
        "mean of the rings; views cut by the range edge: union) or 'union' (mapping.crossings)",
    )
    merge_behind: float = _f(
        5.0,
        "metres behind the ego beyond which a polyline observation leaves the stretch the "
        "instance already covers as it is: the car has passed it, the map holds a nearer view "
        "(mapping.passed; 0: the newest view replaces everything it overlaps)",
    )
    absorb_gate: float = _f(
        1.0,
        "metres; absorption (IC-Mapper's absorb, every method's map_nms): a point within this "
        "gate of a same-class neighbour lies on it",
    )
    absorb_boundary_gate: float = _f(
        1.5,
        "metres; absorb_gate of boundaries (two views of one kerb lie up to 1.5 m apart in the "
        "coarse BEV, two kerbs of a road farther)",
    )
    absorb_overlap: float = _f(
        0.5, "absorption: share of an instance's points lying on a neighbour to join the two"
    )
    absorb_tolerance: float = _f(
        3.0, "absorption: metres a joining polyline merge may move any point of either instance"
    )
    map_nms: bool = _f(
        False,
        "clean-up of the finished map, for every method: absorb every instance that lies on a "
        "same-class neighbour, remove stubs across lanes (mapping.map_nms)",
    )
    verify: bool = _f(
        True,
        "check of the finished map against the drive's own detections, for every method: an "
        "instance in view in >= verify_frames frames and not detected (score >= "
        "track_threshold) in >= verify_share of them is removed (mapping.verify)",
    )
    verify_frames: int = _f(3, "verify: frames an instance must be in view to be checked")
    verify_share: float = _f(
        0.7, "verify: share of the frames in view without a detection that removes an instance"
    )
    stub_length: float = _f(
        15.0,
        "map_nms and drop_stubs: metres under which a divider crossing a longer one is a stub "
        "(0: keep all)",
    )
    stub_angle: float = _f(
        45.0, "map_nms and drop_stubs: degrees at which a stub crosses the longer divider"
    )
    positional_scale: float = _f(
        1.5,
        "metres; positional affinity exp(-chamfer/scale) (no query features, Post-Track); with "
        "assoc_threshold 0.5 a link within scale x ln 2 (1.04 m) of a track's last view",
    )
    # ---- IC-Mapper
    detect_threshold: float = _f(0.1, "score of detections reported per frame (evaluated by AP)")
    track_threshold: float = _f(0.4, "score of detections tracked, fused and merged into the map")
    assoc_threshold: float = _f(0.5, "θ: minimum association score of a match")
    assign_cover: float = _f(
        1.0,
        "metres; positional association (no learned head): the assignment weighs each "
        "admissible pair by how much the detection and the track's last view lie on each other "
        "within this, so of two pieces lying on a track the one sharing more of it continues it "
        "(0: the scores alone)",
    )
    min_hits: int = _f(2, "frames a new track must be seen before it enters the global map")
    confirm_score: float = _f(
        0.7, "detection score at which a new track enters the global map at once (min_hits: 1)"
    )
    reid_distance: float = _f(1.0, "metres; re-identification against the map (0: off)")
    reid_overlap: float = _f(
        0.5, "share of a new track's points within reid_distance of an instance to take its id"
    )
    reid_alias: bool = _f(
        True,
        "re-identification maps a second new piece of an instance matched this frame into it "
        "(false: the piece stays its own track)",
    )
    absorb: bool = _f(
        True,
        "after each step, an instance the step touched and a same-class neighbour it lies on "
        "over most of its length become one (GlobalMap.absorb with the absorb_* settings)",
    )
    fusion_margin: float = _f(
        20.0, "metres around the range for the sampled history (the fusion network's own value)"
    )
    history_points: int = _f(20, "points per sampled history instance (the network's own value)")
    use_association: bool = _f(True, "learned association (false: positional affinity)")
    use_fusion: bool = _f(True, "spatial fusion with the map's history (false: merge as detected)")
    fusion_classes: tuple[int, ...] = _f(
        (0, 1, 2),
        "class indices (data.types.CLASS_NAMES) whose detections the fusion refines; the others "
        "merge as detected, as with use_fusion=false",
    )
    fused_merge: str = _f(
        "splice",
        "how a fused polyline (one that had a history) merges into its instance: 'splice' (it "
        "replaces the stretch it covers within splice_overlap; mapping.splice) or 'fit' (the "
        "engine's curve fit, as an unfused one)",
    )
    beside_gate: float = _f(
        2.0,
        "metres; a lane-line view running beside its instance (most of it farther than this, "
        "mapping.passed.lies_beside) shows another line: its track leaves the instance and the "
        "view goes in as a new one (0: off)",
    )
    drop_stubs: bool = _f(
        True,
        "lane lines do not cross: a new lane-line instance shorter than stub_length that "
        "crosses a longer stored divider at more than stub_angle is not inserted (its track may "
        "enter later with a view along the lanes), and such a stub among the dividers a step "
        "touched and their neighbours is removed (mapping.map_nms.drop_stubs)",
    )
    min_travel: float = _f(
        0.5,
        "metres; a frame whose ego moved less than this (and turned less than "
        "data.types.STILL_TURN degrees) since the last frame that merged merges nothing: a "
        "stopped car sees one view again and again, and its errors would pile into the map (its "
        "detections are still tracked, fused and reported; 0: every frame merges)",
    )
    splice_overlap: float = _f(0.5, "metres within which a spliced fused polyline replaces points")
    fused_clip: bool = _f(
        False,
        "a spliced fused polyline merges only over the stretch its detection covers (the "
        "fusion's extension beyond the detection's ends left out; mapping.splice."
        "clip_to_detected); the tracker keeps the whole (off in the library; the shipped "
        "checkpoint's [mapper] table turns it on: docs/mapping.md, 'Clean maps')",
    )
    # ---- baselines
    baseline_threshold: float = _f(0.3, "score of detections the baselines use and report")
    gate: float = _f(1.5, "Post-Track / VMA: largest Chamfer distance (m) of a link")
    vma_overlap: float = _f(1.0, "VMA: metres within which a detection overlaps its instance")
    cluster_eps: float = _f(3.0, "Cluster & Fit: DBSCAN eps (m)")
    cluster_min_samples: int = _f(5, "Cluster & Fit: DBSCAN min_samples")
    polymerge_buffer: float = _f(1.0, "PolyMerge: overlap buffer (m)")
    polymerge_min_overlap: float = _f(0.3, "PolyMerge: share of a detection that must overlap")
    # ---- city maps (icmapper map --city): merging drive maps in the engine
    city_gate: float = _f(1.0, "city merge: metres within which instances of two maps overlap")
    city_min_overlap: float = _f(
        0.5, "city merge: share of an instance within the gate for two instances to merge"
    )
    city_tolerance: float = _f(
        3.0,
        "city merge: metres a polyline merge may move any point of either instance (or add "
        "away from both); a merge beyond it is refused and the instances stay apart",
    )

    def __post_init__(self) -> None:
        for name in ("detect_threshold", "track_threshold", "assoc_threshold",
                     "baseline_threshold", "confirm_score"):  # fmt: skip
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"MapperConfig.{name} must be in [0, 1], got {v}")
        if self.track_threshold < self.detect_threshold:
            raise ValueError("MapperConfig.track_threshold must be >= detect_threshold")
        for name in ("positional_scale", "spacing", "history_points", "gate", "splice_overlap",
                     "vma_overlap", "cluster_eps", "polymerge_buffer", "city_gate",
                     "city_tolerance", "absorb_tolerance", "absorb_gate",
                     "absorb_boundary_gate"):  # fmt: skip
            if not getattr(self, name) > 0:
                raise ValueError(f"MapperConfig.{name} must be > 0, got {getattr(self, name)}")
        for name in ("min_hits", "cluster_min_samples", "verify_frames"):
            if getattr(self, name) < 1:
                raise ValueError(f"MapperConfig.{name} must be >= 1, got {getattr(self, name)}")
        for name in ("max_age", "reid_distance", "beside_gate", "fusion_margin", "smoothing",
                     "merge_behind", "stub_length", "assign_cover"):  # fmt: skip
            if not getattr(self, name) >= 0:
                raise ValueError(f"MapperConfig.{name} must be >= 0, got {getattr(self, name)}")
        if not 0.0 <= self.min_travel < float("inf"):
            raise ValueError(
                f"MapperConfig.min_travel must be finite and >= 0, got {self.min_travel}"
            )
        if len(set(self.fusion_classes)) != len(self.fusion_classes) or not all(
            0 <= c < NUM_CLASSES for c in self.fusion_classes
        ):
            raise ValueError(
                f"MapperConfig.fusion_classes must be distinct class indices in [0, {NUM_CLASSES}),"
                f" got {list(self.fusion_classes)}"
            )
        if self.fused_merge not in FUSED_MERGES:
            raise ValueError(
                f"MapperConfig.fused_merge must be one of {FUSED_MERGES}, got {self.fused_merge!r}"
            )
        if self.crossing_merge not in CROSSING_MERGES:
            raise ValueError(
                f"MapperConfig.crossing_merge must be one of {CROSSING_MERGES}, "
                f"got {self.crossing_merge!r}"
            )
        if not 0.0 < self.city_min_overlap <= 1.0:
            raise ValueError(
                f"MapperConfig.city_min_overlap must be in (0, 1], got {self.city_min_overlap}"
            )
        if not 0.0 <= self.stub_angle <= 90.0:
            raise ValueError(f"MapperConfig.stub_angle must be in [0, 90], got {self.stub_angle}")
        if not 0.0 < self.verify_share <= 1.0:
            raise ValueError(
                f"MapperConfig.verify_share must be in (0, 1], got {self.verify_share}"
            )
        if not 0.0 < self.absorb_overlap <= 1.0:
            raise ValueError(
                f"MapperConfig.absorb_overlap must be in (0, 1], got {self.absorb_overlap}"
            )
        if not 0.0 < self.reid_overlap <= 1.0:
            raise ValueError(
                f"MapperConfig.reid_overlap must be in (0, 1], got {self.reid_overlap}"
            )
        if not 0.0 < self.polymerge_min_overlap <= 1.0:
            raise ValueError(
                f"MapperConfig.polymerge_min_overlap must be in (0, 1], "
                f"got {self.polymerge_min_overlap}"
            )

    # ---- plain data
    @staticmethod
    def from_dict(table: dict[str, Any], base: MapperConfig | None = None) -> MapperConfig:
        """A config from plain values (unknown names and wrong types raise ValueError);
        fields not given keep ``base``'s values (or the defaults)."""
        return from_table(MapperConfig, table, "mapper", base)

    def to_dict(self) -> dict[str, Any]:
        return to_plain(self)

    @staticmethod
    def for_checkpoint(path: str) -> MapperConfig:
        """The config a learned checkpoint maps with: the defaults, its detection threshold and
        its ``[mapper]`` settings (chosen on validation for that network). The one owner of that
        rule: ``Mapper.from_checkpoint``, the command line and the experiments use it."""
        from icmapper.models.network import checkpoint_mapper_defaults

        table, threshold = checkpoint_mapper_defaults(path)
        return MapperConfig.from_dict(table, MapperConfig(detect_threshold=threshold))

    @staticmethod
    def help() -> dict[str, str]:
        """Field name -> one-line help with its default (for the command line)."""
        return {
            f.name: f"{f.metadata.get('help', '')} (default {f.default})"
            for f in fields(MapperConfig)
        }


#: Settings a user tunes most, given their own flag on `icmapper map` / `compare` (the rest
#: through --set NAME=VALUE).
CLI_FLAGS = (
    "assoc_threshold",
    "track_threshold",
    "detect_threshold",
    "min_hits",
    "smoothing",
    "spacing",
    "baseline_threshold",
)
