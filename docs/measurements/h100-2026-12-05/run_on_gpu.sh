#!/bin/bash
# The device check of 2026-12-05 (a lent H100): the stream on the GPU. 1. the stream track's synthetic part on cuda
# (its figures against the CPU's of docs/measurements/issue28-stream/twentieth-stop/stream.json); 2. a stream step
# against a cold frame on moving content (stream_moving.py); 3. the speed track's stream-fast rows (a static scene).
# $1: a label for the files (the tree that runs). Run from the repository root; kornia travels as wheels (.whl).
# As run on 2026-12-05 the speed line passed --repeats 5, which bench does not take, and failed; it now sets
# TORCH_DEPTH_SR_SPEED_REPEATS.
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl \
    && export PYTHONPATH=/tmp/site:$PWD || exit 1
export PYTHONUNBUFFERED=1
OUT=${OUT:-out/gpu}
L=${1:-head}
mkdir -p "$OUT"
here=docs/measurements/h100-2026-12-05
{ nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader
  python3 -c "import torch, numba, kornia; print('torch', torch.__version__, 'numba', numba.__version__, 'kornia', kornia.__version__)"
  git log -1 --format='tree of %h' 2>/dev/null; } | tee "$OUT/gpu_$L.txt"
timeout 200 python3 -m torch_depth_sr.cli bench --track stream --sets synthetic --methods frame stream --device cuda \
    --per-scene --json "$OUT/stream_cuda_$L.json" 2>&1 | grep -v Warning | tee "$OUT/stream_cuda_$L.txt"
for b in 1 4; do
  timeout 90 python3 $here/stream_moving.py --device cuda --size 480x640 --batch $b --frames 14 --skip 10 \
      --json "$OUT/moving_cuda_${L}_b$b.json" 2>&1 | tee -a "$OUT/moving_cuda_$L.txt"
done
TORCH_DEPTH_SR_SPEED_SIZES=480x640 TORCH_DEPTH_SR_SPEED_BATCHES=1,4 TORCH_DEPTH_SR_SPEED_REPEATS=5 timeout 150 python3 -m torch_depth_sr.cli bench \
    --track speed --methods stream-fast --device cuda --json "$OUT/speed_cuda_$L.json" 2>&1 \
    | tee "$OUT/speed_cuda_$L.txt"
