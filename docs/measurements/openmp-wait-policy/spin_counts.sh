#!/usr/bin/env bash
# How long should torch's idle OpenMP threads spin? The fast and default tiers and kornia's 9x9 filter (torch alone)
# at 640x480, three timed calls each, under four settings in turn, ROUNDS times. From the repository root:
#   bash docs/measurements/openmp-wait-policy/spin_counts.sh [ROUNDS] > docs/measurements/openmp-wait-policy/spin_counts.txt
set -euo pipefail
for i in $(seq 1 "${1:-2}"); do
  for e in GOMP_SPINCOUNT=10000 GOMP_SPINCOUNT=30000 OMP_WAIT_POLICY=PASSIVE GOMP_SPINCOUNT=300000; do
    row=$(env $e TORCH_DEPTH_SR_SPEED_BATCHES=1 TORCH_DEPTH_SR_SPEED_THREADS=2 TORCH_DEPTH_SR_SPEED_REPEATS=3 \
      TORCH_DEPTH_SR_SPEED_SIZES=480x640 torch-depth-sr bench --track speed --methods fast default kornia-jbf9 2>&1 \
      | grep -E "^(fast|default|kornia)" | awk '{printf "%s %s s  ", $1, $4}')
    echo "round $i  $e  $row"
  done
done
