#!/bin/bash
# The second device check of 2026-12-04 (after the constants made on the device): the tiers' CUDA graphs and the
# stream rows at 480x640, where the stages' time goes, and the agreement again. Wheels in .whl/, CPU outputs in .gpuref/.
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl \
    && export PYTHONPATH=/tmp/site:$PWD || exit 1
export PYTHONUNBUFFERED=1
OUT=${OUT:-out/gpu}
mkdir -p "$OUT"
timeout 150 python3 -m torch_depth_sr.evaluation.gpu_report --sizes 480x640 --batch 1 8 --repeats 5 --warmup 2 \
    --out "$OUT" 2>&1 | tee "$OUT/report.log"
timeout 90 python3 docs/measurements/h200-2026-12-04/stages.py 2>&1 | tee "$OUT/stages.txt"
timeout 90 python3 docs/measurements/h200-2026-12-04/agreement.py --compare .gpuref 2>&1 | tee "$OUT/agreement.txt"
