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
