"""fit.py with best's x⁰ search restricted to offsets within CORE of the centre and those on a step-LAT lattice of the
21x21 window (an experiment: monkeypatches cpu_exact.offset_order for stride-1 21x21 searches only):

    CORE=7 LAT=3 python docs/measurements/issue27-tiers/seventeenth-stop/fit_core.py --threads 2 \
        --label best-x0-core7-lat3 --spec preset:best --out fit_core.jsonl
"""
import os, sys, runpy
from pathlib import Path
import numpy as np
ROOT = Path(__file__).resolve().parents[4]
sys.path.insert(0, str(ROOT))
import torch_depth_sr.block_matching.cpu_exact as ce
from torch_depth_sr.block_matching._common import offset_order as orig
CORE, LAT = int(os.environ["CORE"]), int(os.environ["LAT"])
def patched(search_window, stride, include_self):
    o = orig(search_window, stride, include_self)
    if search_window == 21 and stride == 1:
        r = search_window // 2
        keep = []
        for oid in o.tolist():
            dy, dx = oid // search_window - r, oid % search_window - r
            if max(abs(dy), abs(dx)) <= CORE or (dy % LAT == 0 and dx % LAT == 0):
                keep.append(oid)
        return np.array(keep, dtype=np.int32)
    return o
ce.offset_order = patched
sys.argv = ["fit.py"] + sys.argv[1:]
runpy.run_path(str(ROOT / "docs/measurements/issue27-tiers/fit.py"), run_name="__main__")
