#!/usr/bin/env bash
# The GPU checks of the mapper, in one call of the workplace's device tool (a lent GPU machine,
# about 7 minutes at most): run from the repository root on that machine, with the compiled
# extension (python/icmapper/_icmap.abi3.so) and wheels of the packages the machine lacks (.whl/:
# shapely, simplejpeg) carried along. Logs land in $OUT (the device tool brings them back).
#
#   1. `python -m benchmarks pipeline --device cuda --frames 100`: the whole Mapper at paper
#      scale (configs/paper.toml, fresh weights, rasterised ground truth as the segmentation),
#      ms/frame by stage and frames/s end to end (BENCHMARKS.md, 'The whole pipeline at paper
#      scale'); twice, for the spread. The drive (sim:test:1's first sequence) has 44 frames, so
#      at most 43 are timed after the warm-up frame.
#   2. The shipped small checkpoint maps MAP_SOURCE (default sim:test:4) on the GPU and on the
#      CPU (`icmapper map --device ...`); both runs are evaluated (`icmapper eval`) and compared:
#      instances per map, the per-frame predictions, and the Chamfer distance of the GPU's map to
#      the CPU's (the project's global-map CD with the CPU's map as the reference).
#
# How it was called (the results: BENCHMARKS.md, "The whole pipeline at paper scale"; one H200,
# 95 s): the device tool's `run` with
#   command `bash scripts/gpu_pipeline.sh`, carry [python/icmapper/_icmap.abi3.so, .whl]
# where .whl was filled here with
#   python3 -m pip download --no-deps --only-binary=:all: --python-version 3.12 \
#       --implementation cp --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 \
#       -d .whl shapely==2.2.0 simplejpeg==1.9.0
# Tried on a machine without a GPU first, with
#   DEVICE=cpu FRAMES=2 MAP_SOURCE=sim:test:1 PY=.venv/bin/python OUT=/tmp/gpu_out \
#       bash scripts/gpu_pipeline.sh
# (DEVICE: the device of the pipeline benchmark and of the mapping compared with the CPU's;
# FRAMES: the benchmark's --frames; REPEAT: benchmark runs; PY: the Python to use.)
set -uo pipefail
DEVICE=${DEVICE:-cuda}
FRAMES=${FRAMES:-100}
REPEAT=${REPEAT:-2}
MAP_SOURCE=${MAP_SOURCE:-sim:test:4}
PY=${PY:-python3}
OUT=${OUT:-/tmp/gpu-pipeline-out}
WORK=$(mktemp -d /tmp/gpu-pipeline.XXXXXX)
mkdir -p "$OUT"
export OMP_NUM_THREADS=1 PYTHONUNBUFFERED=1
status=0
t_start=$(date +%s)
stamp() { echo "== $* ($(( $(date +%s) - t_start )) s)"; }

if ! "$PY" -c "import shapely, simplejpeg" 2> /dev/null; then
    "$PY" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
        --target /tmp/site .whl/*.whl || exit 1
fi
export PYTHONPATH=/tmp/site:$PWD/python${PYTHONPATH:+:$PYTHONPATH}

{
    stamp "machine"
    nvidia-smi -L 2> /dev/null || echo "(no nvidia-smi)"
    nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader 2> /dev/null
    "$PY" - << 'EOF'
import sys, numpy, torch, shapely, icmapper
print("python", sys.version.split()[0], "| numpy", numpy.__version__, "| torch", torch.__version__,
      "| shapely", shapely.__version__, "| icmapper", icmapper.__file__)
print("cuda available:", torch.cuda.is_available(),
      "|", torch.cuda.get_device_name(0) if torch.cuda.is_available() else "-",
      "| cudnn", torch.backends.cudnn.version() if torch.cuda.is_available() else "-")
EOF
} 2>&1 | tee "$OUT/machine.log"

# 1. the pipeline at paper scale
for r in $(seq 1 "$REPEAT"); do
    stamp "pipeline run $r: benchmarks pipeline --device $DEVICE --frames $FRAMES"
    timeout 150 "$PY" -m benchmarks pipeline --device "$DEVICE" --frames "$FRAMES" 2>&1 \
        | tee "$OUT/pipeline_$r.log" || { echo "pipeline run $r FAILED (rc $?)"; status=1; }
done

# 2. the shipped checkpoint: the GPU's map (run "dev") against the CPU's (run "ref")
for pair in "dev:$DEVICE" "ref:cpu"; do
    name=${pair%%:*} dev=${pair#*:}
    stamp "map $MAP_SOURCE --device $dev"
    timeout 120 "$PY" -m icmapper map --source "$MAP_SOURCE" --device "$dev" \
        --out "$WORK/$name" --no-progress 2>&1 | tee "$OUT/map_$name.log" \
        || { echo "map on $dev FAILED (rc $?)"; status=1; }
    cat "$WORK/$name/icmapper/timing.json" 2> /dev/null && echo
done
{
    s=0
    stamp "eval: the $DEVICE run, then the cpu run"
    timeout 120 "$PY" -m icmapper eval "$WORK/dev/icmapper" "$WORK/ref/icmapper" \
        || { echo "eval FAILED (rc $?)"; s=1; }
    stamp "compare: the $DEVICE maps vs the cpu maps"
    timeout 120 "$PY" - "$WORK/dev/icmapper" "$WORK/ref/icmapper" << 'EOF' \
        || { echo "compare FAILED (rc $?)"; s=1; }
import json, sys
from pathlib import Path
import numpy as np
from icmapper.eval.detection import THRESHOLDS
from icmapper.eval.globalmap import global_metrics, load_global_map

a_dir, b_dir = Path(sys.argv[1]), Path(sys.argv[2])  # a: the GPU's run, b: the CPU's (reference)
run = json.loads((b_dir / "run.json").read_text())
thr = THRESHOLDS[run["range"]]
print(f"{'sequence':<14} {'inst gpu':>8} {'inst cpu':>8} {'frames same':>11} "
      f"{'max |dpts| m':>12} {'max |dscore|':>12} {'CD gpu->cpu m':>13} {'same ids':>8}")
all_a, all_b = [], []
for s in run["sequences"]:
    ma, mb = load_global_map(a_dir / s["global_map"]), load_global_map(b_dir / s["global_map"])
    all_a.append(ma); all_b.append([m[:3] for m in mb])
    pa, pb = np.load(a_dir / s["predictions"]), np.load(b_dir / s["predictions"])
    same = int((pa["counts"] == pb["counts"]).sum())
    if np.array_equal(pa["counts"], pb["counts"]) and np.array_equal(pa["classes"], pb["classes"]):
        dp = float(np.abs(pa["points"] - pb["points"]).max(initial=0.0))
        ds = float(np.abs(pa["scores"] - pb["scores"]).max(initial=0.0))
        ids = bool(np.array_equal(pa["track_ids"], pb["track_ids"]))
    else:
        dp = ds = float("nan"); ids = False
    cd = global_metrics([ma], [[m[:3] for m in mb]], thr)["mCD"]
    print(f"{s['name']:<14} {len(ma):>8} {len(mb):>8} {same:>5}/{len(pa['counts']):<5} "
          f"{dp:>12.2e} {ds:>12.2e} {cd:>13.4f} {str(ids):>8}")
g = global_metrics(all_a, all_b, thr)
print(f"all: {sum(map(len, all_a))} instances on the GPU's maps, {sum(map(len, all_b))} on the "
      f"CPU's; mCD of the GPU's maps to the CPU's {g['mCD']:.4f} m, mGAP {100 * g['mGAP']:.1f}")
EOF
    exit $s
} 2>&1 | tee "$OUT/compare.log" || status=1
rm -rf "$WORK"
stamp "done (status $status)"
exit $status
