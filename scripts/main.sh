#!/usr/bin/env bash
# The main job: sets everything up, then runs IC-Mapper (shipped checkpoint) and every baseline on
# synthetic test cities (never used for training or for choosing the recipe; and on the Argoverse 2
# logs in ../shared/data/av2-mini when present),
# prints the paper-style comparison tables and writes run folders, global maps and pictures to
# out/main/. Usage: bash scripts/main.sh [extra `icmapper compare` args]
set -euo pipefail
cd "$(dirname "$0")/.."
echo "main: setting up .venv: Python dependencies (pip) and the Rust extension (a release build)," \
    "about 3-4 minutes the first time, seconds once built" >&2
start=$SECONDS
bash scripts/setup.sh
echo "main: set up in $((SECONDS - start)) s" >&2
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-2}
OUT=${ICMAPPER_OUT:-out/main}
sources=(--source "sim:test:${ICMAPPER_SIM_SEQS:-4}")
AV2=../shared/data/av2-mini
if [ -d "$AV2" ]; then
    sources+=(--source "av2:$AV2")
else
    echo "note: $AV2 not found; running on synthetic cities only" >&2
fi
rm -rf "$OUT"
echo "main: mapping with every method (icmapper compare), writing $OUT" >&2
.venv/bin/icmapper compare "${sources[@]}" --out "$OUT" "$@"
echo "pictures: $OUT/*/*/*.png   report: $OUT/report.md"
