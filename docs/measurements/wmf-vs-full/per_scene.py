"""Per scene: flying+impulse left of the fitted WMF vs full / trained (bench JSONs). Run with the cvenv python."""
import json
import sys

import opencv_wmf as w

FITTED = (5, 25.5, "EXP", "u8", "mask")
bench = {}
for path in sys.argv[1:]:
    for r in json.load(open(path))["results"]:
        bench.setdefault(r["method"], {})[r["scene"]] = r["flying_left"]
meths = sorted(bench)
print("scene\tsplit\twmf\t" + "\t".join(meths))
worse = {m: [0, 0] for m in meths}
for n in w.ALL:
    fl = w.scene_metrics(n, FITTED)[2]
    split = "held out" if n in w.HELD_OUT else "2006"
    print(f"{n}\t{split}\t{100 * fl:.1f}\t" + "\t".join(f"{100 * bench[m][n]:.1f}" for m in meths))
    for m in meths:
        worse[m][0] += bench[m][n] > fl
        worse[m][1] += (bench[m][n] > fl) and n in w.HELD_OUT
for m in meths:
    print(f"# {m} leaves more than the WMF on {worse[m][0]}/21 scenes ({worse[m][1]}/10 held out)")
