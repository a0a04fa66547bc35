import torch, resource, time
from torch_depth_sr.block_matching import block_match
H,W=1088,1376
x=torch.rand(1,1,H,W); c=torch.rand(1,3,H,W); t=(torch.rand(1,1,H,W)>0.1).float()
r0=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t0=time.perf_counter(); m=block_match(x,c,t); print("time", time.perf_counter()-t0)
print("peak RSS MB", resource.getrusage(resource.RUSAGE_SELF).ru_maxrss/1024, "before", r0/1024)
