#!/usr/bin/env bash
# Sets up a development environment in .venv: Python dependencies and the native extension.
# Idempotent; safe to re-run. Usage: bash scripts/setup.sh
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
    "$PY" -m venv .venv
fi
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q "maturin>=1.7,<2"
# The package with its test extras; maturin builds the Rust extension (release) into the venv.
.venv/bin/python -m pip install -q -e ".[test]"
# The official devkits, test oracles of the real-image readers, without their dependency sets
# (they pin numpy < 2 and shapely 2.0 and pull opencv, numba, kornia, ...): reading needs only
# the test extras above (icmapper.testing.devkits explains the two stand-in modules).
.venv/bin/python -m pip install -q --no-deps "nuscenes-devkit==1.2.0" "av2==0.3.6"
