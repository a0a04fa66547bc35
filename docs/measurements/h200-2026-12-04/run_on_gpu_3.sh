#!/bin/bash
# The third device check of 2026-12-04 (after the device-path re-matching and the item-set fills): the agreement with
# the CPU (the stream on the same frames now), then the report at 480x640 (batch 1 and 8) and 1088x1376 (batch 1).
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl \
    && export PYTHONPATH=/tmp/site:$PWD || exit 1
export PYTHONUNBUFFERED=1
OUT=${OUT:-out/gpu}
mkdir -p "$OUT/vga" "$OUT/large"
timeout 60 python3 docs/measurements/h200-2026-12-04/agreement.py --compare .gpuref 2>&1 | tee "$OUT/agreement.txt"
timeout 110 python3 -m torch_depth_sr.evaluation.gpu_report --sizes 480x640 --batch 1 8 --repeats 5 --warmup 2 \
    --out "$OUT/vga" 2>&1 | grep -v ScatterGatherKernel | tee "$OUT/vga/report.log"
timeout 70 python3 -m torch_depth_sr.evaluation.gpu_report --sizes 1088x1376 --batch 1 --repeats 5 --warmup 2 \
    --out "$OUT/large" 2>&1 | grep -v ScatterGatherKernel | tee "$OUT/large/report.log"
