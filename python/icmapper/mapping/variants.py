"""The learned mapper's variants (paper Table 4) and the settings its fusion network fixes.

Read by ``Mapper.from_checkpoint`` and by the method registry (``mapping.methods``), which lists
each variant as a method without importing the mapper. No I/O.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from icmapper.mapping.config import MapperConfig


@dataclass(frozen=True)
class Variant:
    """A variant of the learned mapper (paper Table 4): temporal detector memory, learned
    association, spatial fusion; one line of help; ``learned_only``: refused without the learned
    detector (on oracle or file detections, without query features and fusion, "no-fusion" is
    "full" and "single-frame" is "base"; "base" is allowed there too and equals "full")."""

    temporal: bool
    use_association: bool
    use_fusion: bool
    help: str
    learned_only: bool = False


#: The learned mapper's variants. Method names: "icmapper" for "full", "icmapper-<variant>".
VARIANTS: dict[str, Variant] = {
    "full": Variant(True, True, True, "IC-Mapper: learned association and spatial fusion"),
    "no-fusion": Variant(True, True, False, "IC-Mapper without spatial fusion", True),
    "base": Variant(
        True, False, False, "the detector, positional tracking, no fusion (StreamMapNet-like)"
    ),
    "single-frame": Variant(
        False, False, False, "like base without temporal memory (MapTR-like)", True
    ),
}


def network_settings(
    config: MapperConfig, fusion_margin: float, history_points: int
) -> MapperConfig:
    """``config`` with the fusion network's history settings; ValueError when ``config`` sets
    other values than the defaults and the network's (the network was trained with its own)."""
    default = MapperConfig()
    for name, value in (("fusion_margin", fusion_margin), ("history_points", history_points)):
        mine = getattr(config, name)
        if mine != value and mine != getattr(default, name):
            raise ValueError(
                f"MapperConfig.{name} = {mine}, but the fusion network was trained with {value}"
            )
    return replace(config, fusion_margin=float(fusion_margin), history_points=int(history_points))
