"""Mapping baselines behind the `MappingMethod` interface, each built on a `DetectionSource`:
Post-Track (post_track), Post-track & VMA-merge (vma), Cluster & Fit (cluster_fit) and a
PolyMerge-style rule-based merger (polymerge)."""

from icmapper.mapping.baselines.cluster_fit import ClusterFit
from icmapper.mapping.baselines.polymerge import PolyMerge
from icmapper.mapping.baselines.post_track import PostTrack
from icmapper.mapping.baselines.vma import VmaMerge

#: Baselines by their `name`.
BASELINES = {cls.name: cls for cls in (PostTrack, VmaMerge, ClusterFit, PolyMerge)}

__all__ = ["BASELINES", "ClusterFit", "PolyMerge", "PostTrack", "VmaMerge"]
