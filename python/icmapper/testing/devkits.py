"""Import the official dataset devkits (``nuscenes-devkit``, ``av2``) as test oracles.

The test extras install both devkits without their dependency sets (``scripts/setup.sh``:
``pip install --no-deps``; their full sets pin numpy < 2 and shapely 2.0 and pull opencv, numba,
kornia, scikit-learn, ...). What reading and camera geometry need is in the extras (pyquaternion,
cachetools, universal-pathlib). Two modules the devkits import at module level but use only for
drawing and metrics, ``cv2`` and ``sklearn.metrics``, are replaced by empty stand-ins when they
are not installed: any drawing call would fail loudly, and no reading path calls them.
"""

from __future__ import annotations

import importlib
import sys
import types


def import_devkit(*modules: str) -> list[types.ModuleType]:
    """Imports the named devkit modules with the stand-ins for ``cv2`` (with
    ``cv2.typing.MatLike``) and ``sklearn.metrics`` in place where those packages are absent, then
    removes the stand-ins from ``sys.modules`` again (the devkit modules keep their references;
    nothing else in the process sees them). ImportError when a devkit is not installed."""
    added = []
    for name in ("cv2", "cv2.typing", "sklearn", "sklearn.metrics"):
        try:
            __import__(name)
        except ImportError:
            sys.modules[name] = types.ModuleType(name)
            added.append(name)
    if "cv2.typing" in added:
        sys.modules["cv2.typing"].MatLike = object  # type: ignore[attr-defined]
        sys.modules["cv2"].typing = sys.modules["cv2.typing"]  # type: ignore[attr-defined]
    if "sklearn.metrics" in added:
        sys.modules["sklearn"].metrics = sys.modules["sklearn.metrics"]  # type: ignore[attr-defined]
    try:
        return [importlib.import_module(m) for m in modules]
    finally:
        for name in added:
            sys.modules.pop(name, None)


#: The distribution (pip name) that provides each top-level module the devkit oracles import.
DISTRIBUTIONS = {"av2": "av2", "nuscenes": "nuscenes-devkit", "pyquaternion": "pyquaternion"}


def require_devkit(*modules: str) -> list[types.ModuleType]:
    """:func:`import_devkit` for a test: the modules, or the end of the test when one does not
    import — a skip only where its devkit is not installed at all and ``CI`` is not true, a
    failure otherwise (``icmapper.testing.required``)."""
    from icmapper.testing.required import installed, missing

    try:
        return import_devkit(*modules)
    except ImportError as exc:
        top = (exc.name or "").split(".")[0]
        if top in DISTRIBUTIONS:  # a devkit module itself: installed or not decides
            dist = DISTRIBUTIONS[top]
        else:  # a dependency of an installed devkit
            named = sorted({m.split(".")[0] for m in modules} & set(DISTRIBUTIONS))
            dist = next((DISTRIBUTIONS[n] for n in named if installed(DISTRIBUTIONS[n])), None)
        missing(f"devkit modules {', '.join(modules)} do not import: {exc}", distribution=dist)
