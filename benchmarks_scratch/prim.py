import time, numpy as np, cv2, torch
H,W=480,640
x=np.random.rand(H,W).astype(np.float32)
def t(f,n=20):
    f(); t0=time.perf_counter()
    for _ in range(n): f()
    return (time.perf_counter()-t0)/n*1e3
print("np sub", t(lambda: x-x))
print("cv2 boxFilter", t(lambda: cv2.boxFilter(x,-1,(5,5),normalize=False,borderType=cv2.BORDER_CONSTANT)))
s=np.random.rand(32,W,21).astype(np.float32)
print("cv2 box 21ch 32rows", t(lambda: cv2.boxFilter(s.reshape(32,W,21),-1,(5,5),normalize=False)))
s2=np.random.rand(H,W,21).astype(np.float32)
print("cv2 box 21ch full", t(lambda: cv2.boxFilter(s2,-1,(5,5),normalize=False)))
print("np sq 21ch full", t(lambda: s2*s2))
T=torch.rand(H*W,441)
print("torch topk (n,441)", t(lambda: torch.topk(T,10,dim=1,largest=False),3))
T2=torch.rand(441,H*W)
print("torch topk (441,n) dim0", t(lambda: torch.topk(T2,10,dim=0,largest=False),3))
xt=torch.rand(1,1,H,W)
print("torch avgpool", t(lambda: torch.nn.functional.avg_pool2d(xt,5,1)))
xt=torch.rand(21,1,H,W)
print("torch avgpool 21", t(lambda: torch.nn.functional.avg_pool2d(xt,5,1)))
print("torch sub 21", t(lambda: xt-xt))
