#!/bin/bash
# the stage tables of two source trees in turn: stage_tables_alternating.sh TREE_BEFORE TREE_AFTER [ROUNDS]
# (640x480, 2 threads, min of 3 rounds each, kornia's 9x9 JBF interleaved; stage_table.py of each tree)
source /work/main/.venv/bin/activate
for i in $(seq ${3:-2}); do
  for T in "$1" "$2"; do
    echo "== $(basename $T) $(date +%H:%M:%S) $(git -C $T rev-parse --short HEAD)"
    (cd /tmp && PYTHONPATH=$T OMP_NUM_THREADS=2 python $T/docs/measurements/issue27-tiers/stage_table.py --repeats 3 \
        --models preset:fast preset:default preset:best --input synthetic sensor 2>/dev/null)
  done
done
