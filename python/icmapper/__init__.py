"""icmapper: online vectorised HD-map construction (IC-Mapper) — detect, track, fuse, merge.

The geometry core and global map store are native (``icmapper._icmap``, Rust); the rest is Python
and plain PyTorch. Importing ``icmapper`` does not import torch.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"

__all__ = ["GlobalMap", "Mapper", "__version__"]

if TYPE_CHECKING:  # pragma: no cover
    from icmapper._icmap import GlobalMap
    from icmapper.mapping.mapper import Mapper


def __getattr__(name: str) -> Any:
    # Lazy attributes keep `import icmapper` cheap (no torch, no extension until needed).
    if name == "GlobalMap":
        from icmapper._icmap import GlobalMap

        return GlobalMap
    if name == "Mapper":
        from icmapper.mapping.mapper import Mapper

        return Mapper
    raise AttributeError(f"module 'icmapper' has no attribute {name!r}")
