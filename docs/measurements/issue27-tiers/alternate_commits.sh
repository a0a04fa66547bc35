#!/usr/bin/env bash
# Alternating runs of an earlier commit and the working tree: a fast stream step and a cold fast frame
# (alternate_one.py), then the DataLoader example. Run from the repository root after `make install`:
#   bash docs/measurements/issue27-tiers/alternate_commits.sh 5e4dfbe 480x640 5 3
# The earlier commit is checked out as a git worktree in a temporary folder; its numba kernels compile once there.
set -euo pipefail
before=$1; size=${2:-480x640}; rounds=${3:-5}; repeats=${4:-3}
root=$(mktemp -d)/before
git worktree add -q "$root" "$before"
trap 'git worktree remove --force "$root"' EXIT
AB_ROOT=$root .venv/bin/python -c "import sys,os; sys.meta_path[:]=[f for f in sys.meta_path if 'editable' not in type(f).__module__ and 'editable' not in getattr(f,'__module__','')]; sys.path.insert(0,os.environ['AB_ROOT']); import torch; from torch_depth_sr.warmup import warmup; warmup(dtypes=(torch.float32,))"
here=docs/measurements/issue27-tiers
for i in $(seq "$repeats"); do
  echo "before $(AB_ROOT=$root .venv/bin/python $here/alternate_one.py "$size" "$rounds")"
  echo "after  $(.venv/bin/python $here/alternate_one.py "$size" "$rounds")"
done
for i in $(seq "$repeats"); do
  echo "before $(AB_ROOT=$root .venv/bin/python -c "import sys,os,runpy; sys.meta_path[:]=[f for f in sys.meta_path if 'editable' not in type(f).__module__ and 'editable' not in getattr(f,'__module__','')]; sys.path.insert(0,os.environ['AB_ROOT']); sys.argv=['x','--workers','2','--frames','16','--size','240','320','--tier','fast']; runpy.run_path(os.environ['AB_ROOT']+'/examples/restore_in_dataloader.py', run_name='__main__')" 2>&1 | grep frames)"
  echo "after  $(.venv/bin/python examples/restore_in_dataloader.py --workers 2 --frames 16 --size 240 320 --tier fast 2>&1 | grep frames)"
done
