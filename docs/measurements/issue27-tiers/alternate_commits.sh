#!/usr/bin/env bash
# Alternating runs of an earlier commit and the working tree: a fast stream step against a cold fast frame
# (docs/measurements/issue28-stream/step_vs_cold.py), then the DataLoader example. From the repository root after
# `make install`:
#   bash docs/measurements/issue27-tiers/alternate_commits.sh 5e4dfbe 480x640 5 3
# The earlier commit is checked out as a git worktree in a temporary folder (before_worktree.sh); its numba kernels
# compile once there.
set -euo pipefail
before=$1; size=${2:-480x640}; rounds=${3:-5}; repeats=${4:-3}
source docs/measurements/issue27-tiers/before_worktree.sh  # $root, $here, $py
steps=(docs/measurements/issue28-stream/step_vs_cold.py --sizes "$size" --rounds "$rounds")
loader=(examples/restore_in_dataloader.py --workers 2 --frames 16 --size 240 320 --tier fast)
for i in $(seq "$repeats"); do
  echo "before: $($py $here/run_at.py "$root" "${steps[@]}" | tail -1)"
  echo "after:  $($py "${steps[@]}" | tail -1)"
done
for i in $(seq "$repeats"); do
  echo "before: $($py $here/run_at.py "$root" "$root/${loader[0]}" "${loader[@]:1}" 2>&1 | grep frames)"
  echo "after:  $($py "${loader[@]}" 2>&1 | grep frames)"
done
