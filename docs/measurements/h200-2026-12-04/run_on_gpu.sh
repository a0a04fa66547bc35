#!/bin/bash
# The device check of 2026-12-04, run by the device tool on a lent H200 from the repository root, with the wheels of
# kornia 0.9.0 and kornia-rs 0.2.0 carried in .whl/ and the CPU outputs of agreement.py --save in .gpuref/.
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl \
    && export PYTHONPATH=/tmp/site:$PWD || exit 1
export PYTHONUNBUFFERED=1
OUT=${OUT:-out/gpu}
mkdir -p "$OUT"
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv | tee "$OUT/gpu.txt"
python3 -c "import torch, kornia, numba; print('torch', torch.__version__, 'kornia', kornia.__version__, 'numba', numba.__version__)" | tee -a "$OUT/gpu.txt"
timeout 120 python3 docs/measurements/h200-2026-12-04/agreement.py --compare .gpuref 2>&1 | tee "$OUT/agreement.txt"
timeout 330 python3 -m torch_depth_sr.evaluation.gpu_report --sizes 480x640 1088x1376 --batch 1 8 --repeats 5 \
    --warmup 2 --out "$OUT" 2>&1 | tee "$OUT/report.log"
