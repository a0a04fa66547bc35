#!/usr/bin/env bash
# The sided-median shortcut (commit 1703240) against the commit before it, alternating: the edge steps timed on what
# the fast tier passes them (time_edge_steps.py), then the DataLoader example (2 workers, 320x240, fast). From the
# repository root after `make install`:
#   bash docs/measurements/issue27-tiers/twelfth-stop/snap_before_after.sh b0908e6 4
set -euo pipefail
before=$1; repeats=${2:-4}
source docs/measurements/issue27-tiers/before_worktree.sh  # $root, $here, $py
echo "edge steps before:"; $py $here/run_at.py "$root" $here/time_edge_steps.py | tail -4
echo "edge steps after:"; $py $here/time_edge_steps.py | tail -4
loader=(examples/restore_in_dataloader.py --workers 2 --frames 16 --size 240 320 --tier fast)
for i in $(seq "$repeats"); do
  echo "before: $($py $here/run_at.py "$root" "${loader[@]}" | tail -1)"
  echo "after:  $($py "${loader[@]}" | tail -1)"
done
