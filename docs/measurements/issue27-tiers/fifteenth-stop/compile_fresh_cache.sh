#!/bin/bash
# First forward (fresh numba cache) and `torch-depth-sr warmup` (fresh cache, both dtypes) of two source trees,
# alternated: compile_fresh_cache.sh TREE_A TREE_B OUT_DIR (writes first_forward_fresh_cache.txt, warmup_fresh_cache.txt)
A=$1; B=$2; D=$3
for T in "$A" "$B" "$A" "$B"; do
  h="== $T $(cd $T && git log --oneline -1 | cut -c1-7) $(date +%H:%M:%S)"
  d=$(mktemp -d); echo "$h" >> $D/first_forward_fresh_cache.txt
  NUMBA_CACHE_DIR=$d PYTHONPATH=$T python $T/docs/measurements/numba-first-use/first_forward.py --no-second 2>&1 \
    | grep -E "first forward|top-level" >> $D/first_forward_fresh_cache.txt
  rm -rf $d; d=$(mktemp -d); echo "$h" >> $D/warmup_fresh_cache.txt
  NUMBA_CACHE_DIR=$d PYTHONPATH=$T python -m torch_depth_sr.cli warmup 2>&1 | grep -v "^$" >> $D/warmup_fresh_cache.txt
  rm -rf $d
done
echo finished >> $D/warmup_fresh_cache.txt
