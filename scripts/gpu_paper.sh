#!/usr/bin/env bash
# The paper-scale run (configs/paper.toml) on one lent GPU machine, in three calls of the workplace's
# device tool (each call at most 10 minutes; the machine stays up between calls that follow one
# another). Run from the repository root on that machine, with the compiled extension
# (python/icmapper/_icmap.abi3.so) and wheels of the packages the machine lacks (.whl/: shapely,
# simplejpeg) carried along. Results land in $OUT (the device tool brings them back).
#
#   bash scripts/gpu_paper.sh start MINUTES   # smoke test (30 steps, one drive mapped), then the
#                                             # run in the background, its steps sized to MINUTES
#   bash scripts/gpu_paper.sh wait SECONDS    # follow it for up to SECONDS (ends when it ends)
#   bash scripts/gpu_paper.sh more STEPS      # resume the run up to STEPS in all (the cosine
#                                             # schedule then spans STEPS)
#   bash scripts/gpu_paper.sh finish          # map 4 test drives, export the weights (bf16, split)
#
# The run reported in python/icmapper/checkpoints/README.md: start 13, wait 540, wait 120, finish
# (500 steps), more 700, finish (700 steps).
#
# On any other machine with a GPU and icmapper installed, the same training is one command:
#   icmapper train --config configs/paper.toml --stage 1 --out runs/paper \
#       --set 'data.source="sim:train:128 + sim-varied:train:128"' --set stage1.steps=N
set -uo pipefail
case ${1:-} in
start | wait | more | finish) ;;
*)
    echo "usage: $0 start MINUTES | wait SECONDS | more STEPS | finish" >&2
    exit 2
    ;;
esac
RUN=/tmp/paper
SOURCE='"sim:train:128 + sim-varied:train:128"'   # the small config's 256 drives
OUT=${OUT:-/tmp/paper-out}
mkdir -p "$OUT" "$RUN"
export OMP_NUM_THREADS=1 PYTHONUNBUFFERED=1
if [ ! -d /tmp/site/shapely ]; then
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
        --target /tmp/site .whl/*.whl || exit 1
fi
export PYTHONPATH=/tmp/site:$PWD/python
icm() { python3 -m icmapper "$@"; }
train() {  # train OUTDIR STEPS [extra --set ...]
    local out=$1 steps=$2
    shift 2
    icm train --config configs/paper.toml --stage 1 --out "$out" --no-progress \
        --set "data.source=$SOURCE" --set data.num_workers=14 --set stage1.steps="$steps" \
        --set ckpt_every=250 --set log_every=25 "$@"
}
progress() {
    tail -n 2 "$RUN/stage1_metrics.csv" 2>/dev/null | cut -c1-160
    nvidia-smi --query-gpu=utilization.gpu,memory.used --format=csv,noheader
}

case ${1:-} in
start)
    minutes=${2:?minutes}
    nvidia-smi --query-gpu=name,memory.total --format=csv,noheader
    t0=$(date +%s)
    train /tmp/smoke 60 --set log_every=20 > "$OUT/smoke.log" 2>&1 || { cat "$OUT/smoke.log"; exit 1; }
    echo "smoke train: $(( $(date +%s) - t0 )) s"; cat /tmp/smoke/stage1_metrics.csv
    icm compare --source sim:val:1 --methods icmapper-base --checkpoint /tmp/smoke/stage1.pt \
        --device cuda --out /tmp/smoke/eval --no-progress > "$OUT/smoke_eval.log" 2>&1 \
        || { tail -n 40 "$OUT/smoke_eval.log"; exit 1; }
    echo "smoke eval ok: $(( $(date +%s) - t0 )) s"
    # steps/s of the last 40 smoke steps (the first 20 hold the workers' start)
    rate=$(tail -n 1 /tmp/smoke/stage1_metrics.csv | awk -F, '{print $NF}')
    steps=$(python3 -c "print(max(100, int($rate * $minutes * 60 * 0.92 / 50) * 50))")
    echo "rate $rate steps/s -> $steps steps for $minutes min"
    setsid nohup bash -c "$(declare -f icm train); SOURCE='$SOURCE'; train $RUN $steps" \
        > "$RUN/train.log" 2>&1 < /dev/null &
    sleep 60; progress
    ;;
wait)
    end=$(( $(date +%s) + ${2:?seconds} ))
    while [ "$(date +%s)" -lt "$end" ] && pgrep -f "icmapper train" > /dev/null; do
        sleep 20
    done
    progress; tail -n 3 "$RUN/train.log"
    cp "$RUN/stage1_metrics.csv" "$RUN/train.log" "$OUT/"
    ;;
more)
    train "$RUN" "${2:?steps}" --resume > "$RUN/more.log" 2>&1
    tail -n 3 "$RUN/more.log"; progress
    ;;
finish)
    pkill -f "icmapper train" && sleep 5  # a run past its time stops at its last checkpoint
    rm -rf "$RUN/eval"
    cp "$RUN/stage1_metrics.csv" "$OUT/"  # (8 files at most come back)
    icm compare --source sim:test:4 --methods icmapper-base,post-track \
        --checkpoint "$RUN/stage1.pt" --device cuda --out "$RUN/eval" --no-progress \
        > "$OUT/eval.log" 2>&1
    tail -n 40 "$OUT/eval.log"
    cp "$RUN/eval/results.json" "$RUN/eval/report.md" "$OUT/" 2>/dev/null
    python3 - "$RUN/stage1.pt" "$OUT" <<'EOF'
import sys, torch
blob = torch.load(sys.argv[1], map_location="cpu", weights_only=True)
blob["optimizer"] = None
blob["model"] = {k: v.to(torch.bfloat16) if v.is_floating_point() else v
                 for k, v in blob["model"].items()}
path = f"{sys.argv[2]}/paper_bf16.pt"
torch.save(blob, path)
data = open(path, "rb").read()
part = 15 * 2**20
for i in range(0, len(data), part):
    open(f"{path}.{i // part}", "wb").write(data[i:i + part])
import os; os.remove(path)
print("weights", len(data), "bytes in", -(-len(data) // part), "parts")
EOF
    ;;
esac
