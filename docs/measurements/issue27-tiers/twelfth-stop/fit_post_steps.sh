set -e
F=docs/measurements/issue27-tiers/fit.py
OUT=docs/measurements/issue27-tiers/twelfth-stop/fit_post_steps.jsonl
.venv/bin/python $F --threads 1 --label default-shipped --base preset:default --spec preset:default --out $OUT
.venv/bin/python $F --threads 1 --label A-fidelity3 --base preset:default --spec 'config:{"fidelity": {"width": 3.0}}' --out $OUT
.venv/bin/python $F --threads 1 --label B-fidelity6 --base preset:default --spec 'config:{"fidelity": {"width": 6.0}}' --out $OUT
.venv/bin/python $F --threads 1 --label C-refit-band1.0 --base preset:default --spec 'config:{"edge_refit": {"band": 1.0}}' --out $OUT
.venv/bin/python $F --threads 1 --label D-refit-band2.5 --base preset:default --spec 'config:{"edge_refit": {"band": 2.5}}' --out $OUT
.venv/bin/python $F --threads 1 --label E-snap-share0.7 --base preset:default --spec 'config:{"edge_snap": {"share": 0.7}}' --out $OUT
