"""What one ``Mapper`` run counts: the stages of a step (timed), the counters of what the merge
did, and the id range of reported but untracked detections.

A leaf of ``mapping``: the mapper and its saved state (``state``) both read it, so neither needs
the other at run time. No I/O.
"""

from __future__ import annotations

from dataclasses import dataclass, field

#: The stages of one step, in order (timed in ``MapperStats.seconds``).
STAGES = ("detector", "association", "tracking", "sampling", "fusion", "merge")
#: Stages that run neural networks (the rest is tracking and geometry).
NETWORK_STAGES = ("detector", "association", "fusion")

#: Ids of detections that are reported (score >= detect_threshold) but not tracked start here, so
#: they never collide with track ids (the run format needs an id >= 0 for every prediction).
UNTRACKED_ID_BASE = 1 << 40


@dataclass
class MapperStats:
    """Counters of one sequence (for logs and tests)."""

    frames: int = 0
    #: seconds spent per stage (STAGES)
    seconds: dict[str, float] = field(default_factory=lambda: dict.fromkeys(STAGES, 0.0))
    inserted: int = 0
    merged: int = 0
    reidentified: int = 0  # new tracks renamed to a global instance's id
    aliased: int = 0  # new tracks mapped into an instance already matched this frame
    split: int = 0  # tracks whose view ran beside their instance: a new instance (beside_gate)
    absorbed: int = 0  # instances absorbed into a same-class neighbour (``mapping.absorb``)
    stubs: int = 0  # lane-line stubs across the lanes removed (``drop_stubs``, mapping.map_nms)
    still: int = 0  # frames that merged nothing: the ego stood still (``min_travel``)
    merge_failures: int = 0
    failures: list[str] = field(default_factory=list)

    def note_failure(self, frame_index: int, target: int, exc: BaseException) -> None:
        """Counts a rejected insert or merge (degenerate geometry) and keeps the first 20."""
        self.merge_failures += 1
        if len(self.failures) < 20:
            self.failures.append(f"frame {frame_index}, id {target}: {exc}")
