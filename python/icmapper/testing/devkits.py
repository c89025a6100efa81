"""Import the official dataset devkits (``nuscenes-devkit``, ``av2``) as test oracles.

The test extras install both devkits without their dependency sets (``scripts/setup.sh``:
``pip install --no-deps``; their full sets pin numpy < 2 and shapely 2.0 and pull opencv, numba,
kornia, scikit-learn, ...). What reading and camera geometry need is in the extras (pyquaternion,
cachetools, universal-pathlib). Two modules the devkits import at module level but use only for
drawing and metrics, ``cv2`` and ``sklearn.metrics``, are replaced by empty stand-ins when they
are not installed: any drawing call would fail loudly, and no reading path calls them.
"""

from __future__ import annotations

import sys
import types


def _stub(name: str) -> None:
    try:
        __import__(name)
    except ImportError:
        sys.modules[name] = types.ModuleType(name)


def prepare_devkit_imports() -> None:
    """Installs the stand-ins for ``cv2`` (with ``cv2.typing.MatLike``) and ``sklearn.metrics``
    where those packages are absent; idempotent."""
    for name in ("cv2", "cv2.typing", "sklearn", "sklearn.metrics"):
        _stub(name)
    cv2, typing_mod = sys.modules["cv2"], sys.modules["cv2.typing"]
    if not hasattr(typing_mod, "MatLike"):
        typing_mod.MatLike = object  # type: ignore[attr-defined]
    if not hasattr(cv2, "typing"):
        cv2.typing = typing_mod  # type: ignore[attr-defined]
    sklearn = sys.modules["sklearn"]
    if not hasattr(sklearn, "metrics"):
        sklearn.metrics = sys.modules["sklearn.metrics"]  # type: ignore[attr-defined]
