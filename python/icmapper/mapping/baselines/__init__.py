"""Mapping baselines behind the `MappingMethod` interface, each built on a `DetectionSource` with
its settings from the shared `MapperConfig`, each registered in `icmapper.mapping.methods`:
Post-Track (post-track), Post-track & VMA-merge (vma), Cluster & Fit (cluster-fit) and a
PolyMerge-style rule-based merger (polymerge)."""

from icmapper.mapping.baselines.post_track import PostTrack  # isort: skip  (table order)
from icmapper.mapping.baselines.vma import VmaMerge  # isort: skip
from icmapper.mapping.baselines.cluster_fit import ClusterFit  # isort: skip
from icmapper.mapping.baselines.polymerge import PolyMerge  # isort: skip

__all__ = ["ClusterFit", "PolyMerge", "PostTrack", "VmaMerge"]
