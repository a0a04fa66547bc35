"""The re-matching kernel of the thirteenth stop that was not kept (``refine_rows_not_kept.patch``: every window
offset of a row at once, then each pixel's candidates) against the shipped one (``_refine``), on the speed track's
640x480 frame, 10 previous matches of a 7x7 window: whether the lists are the same, then both timed in turn in one
process, 15 rounds (min and median, ms). Run with the patch applied, then revert it:

    git apply docs/measurements/issue27-tiers/thirteenth-stop/refine_rows_not_kept.patch
    python docs/measurements/issue27-tiers/thirteenth-stop/time_refine_rows.py 1   # torch threads
    git apply -R docs/measurements/issue27-tiers/thirteenth-stop/refine_rows_not_kept.patch

It runs on the code it was written for (``git checkout f4ae940`` first): the fifteenth stop changed ``_refine``'s
arguments and the patch no longer applies.
"""
import torch, time, numpy as np, sys
torch.set_num_threads(int(sys.argv[1]))
from torch_depth_sr.evaluation.speed import make_inputs
from torch_depth_sr.block_matching import block_match
import torch_depth_sr.block_matching.refine_cpu as RC
from torch_depth_sr.block_matching.cpu_exact import padded_planes
from torch_depth_sr.native import run_range, kernel_threads
y,rgb,gt = make_inputs(480,640,1)
x = y/5.0; trust = (y>0).float()
m = block_match(x, rgb, trust, block_size=3, search_window=7, k=10, backend="numba")
xp,tp,cp,use_t = padded_planes(x, rgb, trust, 1, 3)
prev = m.index.numpy().astype(np.int64)
consts = np.array([[400/3/9, 1/9]], np.float32)
h,w=480,640
tA=np.empty((1,h,w,10),np.float32); iA=np.empty((1,h,w,10),np.int32)
tB=tA.copy(); iB=iA.copy()
def old():
    kernel_threads(); RC._refine(xp,tp,cp,use_t,h,w,1,3,prev,0,False,consts,tA,iA)
def new():
    run_range(RC._refine_rows, h, xp,tp,cp,use_t,h,w,1,3,prev,0,False,consts,tB,iB, shares=2)
old(); new()
print("same", np.array_equal(tA,tB), np.array_equal(iA,iB))
res={"old":[], "new":[]}
for rep in range(15):
    for name,f in (("old",old),("new",new)):
        t=time.perf_counter(); f(); res[name].append(time.perf_counter()-t)
for k,v in res.items(): v=sorted(v); print(k, "min %.1f median %.1f"%(v[0]*1000, v[7]*1000))
