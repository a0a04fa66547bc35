"""flying_left / RMSE / MAE of bench runs (per-scene JSON), mean over scenes as bench's summary: all 21, held out, 2006."""
import json
import sys
from collections import defaultdict

HELD_OUT = {"Art", "Books", "Dolls", "Laundry", "Moebius", "Reindeer", "Cones", "Teddy", "Tsukuba", "Venus"}
for path in sys.argv[1:]:
    d = json.load(open(path))
    by = defaultdict(list)
    for r in d["results"]:
        by[r["method"]].append(r)
    for meth, rs in by.items():
        for sub, keep in (("all 21", lambda s: True), ("held out (10)", lambda s: s in HELD_OUT),
                          ("2006 (11)", lambda s: s not in HELD_OUT)):
            sel = [r for r in rs if keep(r["scene"])]
            m = {k: sum(r[k] for r in sel) / len(sel) for k in ("rmse", "mae", "flying_left")}
            print(f"{path} [{d['metadata']['commit'][:7]}] {meth:8s} {sub:14s} n={len(sel):2d} RMSE {m['rmse']:.3f}  "
                  f"MAE {m['mae']:.3f}  flying+impulse left {100 * m['flying_left']:.1f} %")
