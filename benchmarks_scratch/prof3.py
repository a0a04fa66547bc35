import torch, time
torch.set_num_threads(1)
from torch_depth_sr.block_matching import block_match
H,W=480,640
yy=torch.linspace(0,1,H).view(H,1); xx=torch.linspace(0,1,W).view(1,W)
x=(50*yy+30*xx+2*torch.randn(H,W)).view(1,1,H,W); c=torch.rand(1,3,H,W)
xs=torch.rand(1,1,H,W)*100
for name,args in [("depth only",(x,None,None)),("rgb",(x,c,None)),("rand depth only",(xs,None,None))]:
  for cr in (8,480):
    block_match(*args,chunk_rows=cr)
    t0=time.perf_counter(); block_match(*args,chunk_rows=cr); dt=time.perf_counter()-t0
    print(name, cr, dt, dt/(H*W*440)*1e9, "ns/pix-offset")
