#!/usr/bin/env bash
# Issue 28, thirtieth stop: the README's speed command (and the stream rows) with torch's OpenMP threads spinning as
# libgomp's default (GOMP_SPINCOUNT=300000), asleep (OMP_WAIT_POLICY=PASSIVE) and as the package now chooses
# (nothing set: GOMP_SPINCOUNT=10000, torch_depth_sr/_openmp.py), in turn, ROUNDS times. Run from the repository root:
#   bash docs/measurements/openmp-wait-policy/alternate.sh [ROUNDS]
set -euo pipefail
out=docs/measurements/openmp-wait-policy
for i in $(seq 1 "${1:-2}"); do
  for mode in spin300000 passive package; do
    case $mode in
      spin300000) e="GOMP_SPINCOUNT=300000" ;;
      passive) e="OMP_WAIT_POLICY=PASSIVE" ;;
      package) e="TORCH_DEPTH_SR_UNUSED=1" ;;
    esac
    env $e TORCH_DEPTH_SR_SPEED_BATCHES=1 TORCH_DEPTH_SR_SPEED_THREADS=2 TORCH_DEPTH_SR_SPEED_REPEATS=2 \
      TORCH_DEPTH_SR_SPEED_SIZES=480x640 torch-depth-sr bench --track speed \
      --methods fast default full best kornia-jbf9 stream-fast-moving > "$out/tiers_480x640_${mode}_$i.txt" 2>&1
    env $e TORCH_DEPTH_SR_SPEED_BATCHES=1 TORCH_DEPTH_SR_SPEED_THREADS=2 TORCH_DEPTH_SR_SPEED_REPEATS=9 \
      TORCH_DEPTH_SR_SPEED_SIZES=370x463 torch-depth-sr bench --track speed \
      --methods stream-fast-moving > "$out/stream_370x463_${mode}_$i.txt" 2>&1
  done
done
