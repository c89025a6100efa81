#!/usr/bin/env bash
# Sets everything up and runs the whole test suite: Rust (cargo test) then Python (pytest).
# Usage: bash scripts/test.sh [extra pytest args]
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
cargo test --workspace --exclude icmap-py --release
.venv/bin/python -m pytest -q "$@"
