#!/bin/bash
# the DataLoader example of two source trees alternated: dataloader_alternating.sh TREE_A TREE_B [ROUNDS]; prints "tree rate_with_startup steady_rate"
# alternate the DataLoader example between two trees: A=$1 B=$2, N=$3 rounds
source /work/main/.venv/bin/activate
for i in $(seq ${3:-6}); do
  for T in "$1" "$2"; do
    r=$(cd /tmp && PYTHONPATH=$T python $T/examples/restore_in_dataloader.py --workers 2 --frames 16 --size 240 320 --tier fast 2>/dev/null | sed -E 's/.*workers: ([0-9.]+) frames\/s .*steady ([0-9.]+) .*/\1 \2/')
    echo "$(basename $T) $r"
  done
done
