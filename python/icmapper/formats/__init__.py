"""Prediction files: readers and writers of the field's per-frame prediction formats and of
icmapper's own (docs/eval.md, "Prediction files").

One module per external format (``streammapnet.py``, ``maptr.py``) and icmapper's
(``icmapper_json.py``), each registering a ``PredictionFormat`` (``registry.py``); ``frames.py``
names a source's frames by token and timestamp; ``source.py`` turns a file into the detection
input of every mapping method; ``export.py`` writes a run folder's predictions in a format;
``cli.py`` is ``icmapper export``. Nothing here runs a network or a mapping method.
"""

from icmapper.formats.registry import (
    PredictionFormat,
    formats,
    formats_help,
    get_format,
    read_predictions,
    register_format,
)
from icmapper.formats.types import PredictedFrame, PredictionFileError, PredictionSet

# The built-in formats register themselves on import (the registry never imports them).
import icmapper.formats.icmapper_json  # noqa: E402, F401  # isort: skip
import icmapper.formats.maptr  # noqa: E402, F401  # isort: skip
import icmapper.formats.streammapnet  # noqa: E402, F401  # isort: skip

__all__ = [
    "PredictedFrame",
    "PredictionFileError",
    "PredictionFormat",
    "PredictionSet",
    "formats",
    "formats_help",
    "get_format",
    "read_predictions",
    "register_format",
]
