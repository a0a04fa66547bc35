set -e
F=docs/measurements/issue27-tiers/fit.py
OUT=docs/measurements/issue27-tiers/twelfth-stop/fit_support_tol_between.jsonl
for tol in 2.5 3.0 3.5; do
  .venv/bin/python $F --threads 1 --label fast-support-tol$tol --base preset:fast --spec "config:{\"singular\": {\"support_tol\": $tol}}" --out $OUT
done
.venv/bin/python $F --threads 1 --label best-support-tol3.5 --base preset:best --spec 'config:{"singular": {"support_tol": 3.5}}' --out $OUT
