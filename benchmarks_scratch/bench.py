import torch, time, sys
from torch_depth_sr.block_matching import block_match
torch.manual_seed(0)
def bench(H,W,trust=False,stride=1,chunk=None,n=3,backend="auto"):
    yy=torch.linspace(0,1,H).view(H,1); xx=torch.linspace(0,1,W).view(1,W)
    x=(50*yy+30*xx+2*torch.randn(H,W)).view(1,1,H,W)
    c=torch.rand(1,3,H,W)
    t=(torch.rand(1,1,H,W)>0.1).float() if trust else None
    block_match(x,c,t,5,21,10,1.0,1.0,chunk_rows=chunk,search_stride=stride,backend=backend)
    t0=time.perf_counter()
    for _ in range(n): block_match(x,c,t,5,21,10,1.0,1.0,chunk_rows=chunk,search_stride=stride,backend=backend)
    return (time.perf_counter()-t0)/n
for a in sys.argv[1:]:
    print(a, eval(a))
