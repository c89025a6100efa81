"""The repository's shell scripts: each parses, and the GPU run's script refuses a bad phase
before it touches anything (it runs on a lent machine: scripts/gpu_paper.sh)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SCRIPTS = sorted((REPO / "scripts").glob("*.sh"))


@pytest.mark.parametrize("script", SCRIPTS, ids=[s.name for s in SCRIPTS])
def test_script_parses(script: Path) -> None:
    bash = shutil.which("bash")
    assert bash is not None
    done = subprocess.run([bash, "-n", str(script)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


@pytest.mark.parametrize("args", [[], ["train"], ["Start", "13"]])
def test_gpu_paper_refuses_a_bad_phase(args: list[str], tmp_path: Path) -> None:
    done = subprocess.run(
        ["bash", str(REPO / "scripts" / "gpu_paper.sh"), *args],
        capture_output=True, text=True, cwd=tmp_path,
        env={"PATH": "/usr/bin:/bin", "OUT": str(tmp_path / "out")},
    )  # fmt: skip
    assert done.returncode == 2
    assert "usage:" in done.stderr and "start MINUTES" in done.stderr
    assert not any(tmp_path.iterdir())  # nothing made before the check: no $OUT, no install
