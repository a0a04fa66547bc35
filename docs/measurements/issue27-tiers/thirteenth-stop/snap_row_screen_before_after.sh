#!/usr/bin/env bash
# The edge snapping's row-wise screen that was not kept (snap_row_screen_not_kept.patch) against the commit it was
# made on, alternating, twice: the edge steps timed on what the fast tier passes them (time_edge_steps.py). From the
# repository root after `make install`, the patch applied in the working tree (revert it after):
#   git apply docs/measurements/issue27-tiers/thirteenth-stop/snap_row_screen_not_kept.patch
#   bash docs/measurements/issue27-tiers/thirteenth-stop/snap_row_screen_before_after.sh HEAD
#   git apply -R docs/measurements/issue27-tiers/thirteenth-stop/snap_row_screen_not_kept.patch
set -euo pipefail
before=$1
source docs/measurements/issue27-tiers/before_worktree.sh  # $root, $here, $py
for i in 1 2; do
  echo "before:"; $py $here/run_at.py "$root" $here/time_edge_steps.py | tail -4
  echo "after (the screen):"; $py $here/time_edge_steps.py | tail -4
done
