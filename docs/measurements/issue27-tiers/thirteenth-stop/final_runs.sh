#!/usr/bin/env bash
# The thirteenth stop's closing measurements, from the repository root after `make install`, the machine otherwise
# idle: two runs of the speed track at 640x480 (the issue's measure) and four of the DataLoader example (fast tier,
# 2 workers, 320x240), one after the other. Writes next to this script.
#   bash docs/measurements/issue27-tiers/thirteenth-stop/final_runs.sh
set -euo pipefail
here=docs/measurements/issue27-tiers/thirteenth-stop
export TORCH_DEPTH_SR_SPEED_BATCHES=1 TORCH_DEPTH_SR_SPEED_THREADS=2 TORCH_DEPTH_SR_SPEED_REPEATS=2 \
    TORCH_DEPTH_SR_SPEED_SIZES=480x640
for run in 1 2; do
  .venv/bin/torch-depth-sr bench --track speed --methods fast default full best kornia-jbf9 \
      --json $here/speed_640x480_run$run.json | tail -8 > $here/speed_640x480_run$run.txt
done
{
  echo "# python examples/restore_in_dataloader.py --workers 2 --frames 16 --size 240 320 --tier fast ($(date -u +%F), four runs)"
  for run in 1 2 3 4; do
    .venv/bin/python examples/restore_in_dataloader.py --workers 2 --frames 16 --size 240 320 --tier fast | tail -1
  done
} > $here/dataloader.txt
cat $here/speed_640x480_run*.txt $here/dataloader.txt
