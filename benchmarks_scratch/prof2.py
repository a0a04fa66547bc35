import numpy as np, cv2, time
from numpy.lib.stride_tricks import sliding_window_view as swv
rows=64; W=640; S=21; G=21; k=10
xp=np.random.rand(rows+4+20, W+4+20).astype(np.float32)
xa=xp[10:10+rows+4, 10:10+W+4]
def t(f,n=20):
    f(); t0=time.perf_counter()
    for _ in range(n): f()
    return (time.perf_counter()-t0)/n*1e3
vb=swv(xp[10:10+rows+4], W+4, axis=1)  # (rows+4, 21, W+4)
vb=vb.transpose(1,0,2)
print(vb.shape)
print("sub GHW", t(lambda: xa[None]-vb))
e=xa[None]-vb
def loop():
    out=np.empty((G,rows+4,W+4),np.float32)
    for g in range(G): np.subtract(xa, xp[10:10+rows+4, g:g+W+4], out=out[g])
    return out
print("sub loop", t(loop))
print("square", t(lambda: np.square(e,out=e)))
e2=e.reshape(-1,W+4)
print("box stacked", t(lambda: cv2.boxFilter(e2,-1,(5,5),normalize=False,borderType=cv2.BORDER_REPLICATE)))
print("per-dy scale factor", 21*480/rows)
