"""Hardening of the geometry engine (issue 14, points 1-5): every case the fuzzer, the kill-mid-save
runs and the contract audit found, as a regression test. Every engine entry point returns or raises
within a bounded time (pytest-timeout marks); a case that once hung or aborted the process runs in
a child interpreter with a wall-clock and a memory limit, so a regression fails the test instead of
freezing or killing the suite.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import textwrap
from pathlib import Path

import icmapper
import numpy as np
import pytest

# The ring of ~1e-299 m that made polygon_union spin for 15 CPU-minutes (issue 14, point 1).
TINY_RING = [
    [-4.1006077439108852e-299, 1.1037331569773797e-299],
    [-4.3541446871708736e-299, 7.2194332142851638e-300],
    [-4.2127516405641947e-299, 6.3347407334057527e-300],
]
SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])  # (4, 2)
CHILD_MEMORY = 4 << 30  # bytes of address space for a child interpreter


def _limit_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (CHILD_MEMORY, CHILD_MEMORY))


def run_child(code: str, timeout: float = 60.0) -> subprocess.CompletedProcess[str]:
    """Runs ``code`` in a fresh interpreter that imports this tree's ``icmapper``, with at most
    ``timeout`` seconds of wall-clock time and ``CHILD_MEMORY`` bytes of address space. A hang
    raises ``subprocess.TimeoutExpired`` (the child is killed), an abort shows in the return
    code."""
    package_root = Path(icmapper.__file__).resolve().parents[1]
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(package_root), env.get("PYTHONPATH", "")])
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
        preexec_fn=_limit_memory,
    )


def ring_area(r: np.ndarray) -> float:
    """Signed area of a ring (k, 2) by the shoelace formula."""
    x, y = r[:, 0], r[:, 1]  # (k,), (k,)
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


# ---------------------------------------------------------------------------------------------
# 1. polygon_union hung on a tiny ring


@pytest.mark.timeout(120)
def test_polygon_union_of_a_tiny_ring_returns() -> None:
    """Alone, beside a square, and among three rings (fast path, overlay, second try): each
    union returns in seconds; the tiny ring's area underflows to zero, so it contributes
    nothing."""
    code = f"""
        import json
        import numpy as np
        from icmapper import geom
        tiny = np.array({TINY_RING!r})
        sq = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
        out = [geom.polygon_union(rings) for rings in ([tiny], [tiny, sq], [tiny, sq, sq + 0.5])]
        print(json.dumps([[r.tolist() for r in u] for u in out]))
    """
    proc = run_child(code, timeout=60)
    assert proc.returncode == 0, proc.stderr
    alone, beside, three = json.loads(proc.stdout)
    assert alone == []
    assert len(beside) == 1 and abs(ring_area(np.array(beside[0])) - 1.0) < 1e-12
    assert len(three) == 1 and abs(ring_area(np.array(three[0])) - 1.75) < 1e-12


@pytest.mark.timeout(120)
def test_polygon_union_is_scale_invariant_down_to_subnormals() -> None:
    """Two overlapping squares scaled by 10**e, e from -30 to -320 (the subnormals), in a child
    interpreter: every union returns, and while its area is representable it is the union at
    1 m scaled (1.75 s**2)."""
    exponents = [-30, -150, -271, -290, -300, -305, -310, -320]
    code = f"""
        import json
        import numpy as np
        from icmapper import geom
        sq = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
        out = []
        for e in {exponents!r}:
            s = 10.0 ** e
            out.append([r.tolist() for r in geom.polygon_union([sq * s, (sq + 0.5) * s])])
        print(json.dumps(out))
    """
    proc = run_child(code, timeout=60)
    assert proc.returncode == 0, proc.stderr
    for e, u in zip(exponents, json.loads(proc.stdout), strict=True):
        assert all(len(r) >= 3 for r in u), e
        if e >= -150:
            s = 10.0**e
            assert len(u) == 1, e
            assert abs(ring_area(np.array(u[0])) / (s * s) - 1.75) < 1e-6, e
