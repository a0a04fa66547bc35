#!/bin/bash
# The second device check of 2026-12-05: the tree before (b984985, its package carried in .base/) and this tree (the
# later layers on the whole frame off the CPU) in turn on the same machine: a stream step against a cold frame on
# moving content (stream_moving.py, batch 1 and 4) and the speed track's stream-fast rows (a static scene), then the
# stream track's synthetic part with this tree. Run from the repository root; kornia travels as wheels (.whl).
# Before the device call, here: echo /.base/ >> .git/info/exclude; mkdir -p .base && git archive b984985
# torch_depth_sr | tar -x -C .base; the wheels as in docs/measurements/h200-2026-12-04 (kornia 0.9.0, kornia_rs 0.2.0,
# cp312 manylinux) into .whl; then run with carry [".whl", ".base"].
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit 1
export PYTHONUNBUFFERED=1
OUT=${OUT:-out/gpu}
ROOT=$PWD
here=$ROOT/docs/measurements/h100-2026-12-05
mkdir -p "$OUT"
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader | tee "$OUT/gpu_2.txt"
for round in 1 2; do
  for L in base new; do
    pkg=$ROOT; [ $L = base ] && pkg=$ROOT/.base
    cd "$pkg" || exit 1  # python -m puts the working directory first on the path: the tree of this round
    export PYTHONPATH=/tmp/site:$pkg
    timeout 80 python3 $here/stream_moving.py --device cuda --size 480x640 --batch 1 --frames 24 --skip 12 \
        --json "$OUT/moving_${L}_b1_r$round.json" 2>&1 | sed "s/^/$L r$round /" | tee -a "$OUT/moving_2.txt"
    [ $round = 1 ] && timeout 80 python3 $here/stream_moving.py --device cuda --size 480x640 --batch 4 --frames 20 \
        --skip 12 --json "$OUT/moving_${L}_b4.json" 2>&1 | sed "s/^/$L /" | tee -a "$OUT/moving_2.txt"
    [ $round = 1 ] && TORCH_DEPTH_SR_SPEED_SIZES=480x640 TORCH_DEPTH_SR_SPEED_BATCHES=1,4 TORCH_DEPTH_SR_SPEED_REPEATS=5 \
        timeout 100 python3 -m torch_depth_sr.cli bench --track speed --methods stream-fast --device cuda \
        --json "$OUT/speed_${L}.json" 2>&1 | grep -v Warning | tail -8 | sed "s/^/$L /" | tee -a "$OUT/speed_2.txt"
  done
done
cd "$ROOT" && export PYTHONPATH=/tmp/site:$ROOT
timeout 120 python3 -m torch_depth_sr.cli bench --track stream --sets synthetic --methods frame stream --device cuda \
    --json "$OUT/stream_cuda_new.json" 2>&1 | grep -v Warning | tail -6 | tee "$OUT/stream_cuda_new.txt"
