import torch, itertools
from torch_depth_sr.block_matching import block_match, block_match_reference
torch.manual_seed(0)
for B,H,W,S,bs,k,rgb,trust,incl,dt,stride,backend in [
  (2,13,17,7,3,5,True,True,False,torch.float32,1,"c"),
  (2,13,17,7,3,5,True,True,False,torch.float32,1,"torch"),
  (1,16,12,9,5,8,False,False,True,torch.float64,1,"c"),
  (1,16,12,9,5,8,True,False,True,torch.float64,2,"torch"),
  (1,16,12,9,5,3,True,True,False,torch.float64,2,"c"),
]:
    x=torch.rand(B,1,H,W,dtype=dt); c=torch.rand(B,3,H,W,dtype=dt) if rgb else None
    t=(torch.rand(B,1,H,W)>0.3).to(dt) if trust else None
    a=block_match(x,c,t,bs,S,k,0.7,0.5,incl,chunk_rows=5,search_stride=stride,backend=backend)
    r=block_match_reference(x,c,t,bs,S,k,0.7,0.5,incl,search_stride=stride)
    print((a.dist-r.dist).abs().max().item(), (a.index!=r.index).float().mean().item(), (a.weight-r.weight).abs().max().item())
