"""The shipped checkpoint as package data: ``DEFAULT_CHECKPOINT`` is the path of ``small.pt``
(the networks of ``configs/small.toml``; how it was made and what it measures: ``README.md``
beside it), found through ``importlib.resources`` so that an installed wheel finds it too."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

#: The shipped checkpoint (``icmapper map`` / ``compare`` use it when no ``--checkpoint`` is given).
DEFAULT_CHECKPOINT: Path = Path(str(resources.files(__name__) / "small.pt"))
