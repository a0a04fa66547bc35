#!/bin/bash
# the speed track's stream step against a cold frame (stream-fast, kornia's 9x9 JBF), two source trees in turn:
#   stream_step_alternating.sh TREE_BEFORE TREE_AFTER OUT_DIR [ROUNDS]
# each run: 463x370, 640x480, 1376x1088, 2 threads, 2 paired rounds (the README's speed-track settings)
source /work/main/.venv/bin/activate
out=$(realpath -m "$3"); mkdir -p "$out"
for i in $(seq ${4:-2}); do
  for T in "$1" "$2"; do
    rev=$(git -C "$T" rev-parse --short HEAD)
    echo "== round $i, tree $rev, $(date +%H:%M:%S)"
    (cd /tmp && PYTHONPATH=$T TORCH_DEPTH_SR_SPEED_BATCHES=1 TORCH_DEPTH_SR_SPEED_THREADS=2 TORCH_DEPTH_SR_SPEED_REPEATS=2 \
        TORCH_DEPTH_SR_SPEED_SIZES=370x463,480x640,1088x1376 python -m torch_depth_sr.cli bench --track speed \
        --methods stream-fast kornia-jbf9 --json "$out/speed_${rev}_round$i.json" 2>/dev/null | grep -E "^stream-fast|^kornia")
  done
done
