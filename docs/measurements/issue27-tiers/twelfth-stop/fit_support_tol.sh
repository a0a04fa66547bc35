set -e
F=docs/measurements/issue27-tiers/fit.py
OUT=docs/measurements/issue27-tiers/twelfth-stop/fit_support_tol.jsonl
for t in fast default best; do
  .venv/bin/python $F --threads 1 --label $t-shipped --base preset:$t --spec preset:$t --out $OUT
  .venv/bin/python $F --threads 1 --label $t-support-tol4 --base preset:$t --spec 'config:{"singular": {"support_tol": 4.0}}' --out $OUT
done
