import numpy as np, cv2, time
from numpy.lib.stride_tricks import sliding_window_view as swv
rows=36; W=640; S=21; G=21; k=10
xp=np.random.rand(rows+4+20, W+4+20).astype(np.float32)
xa=xp[10:10+rows+4, 10:10+W+4][:,:,None]
def t(f,n=20):
    f(); t0=time.perf_counter()
    for _ in range(n): f()
    return (time.perf_counter()-t0)/n*1e3
vb=swv(xp[10:10+rows+4], S, axis=1)
print("sub", t(lambda: xa-vb))
e=xa-vb
print("square", t(lambda: np.square(e,out=e)))
print("box", t(lambda: cv2.boxFilter(e,-1,(5,5),normalize=False,borderType=cv2.BORDER_REPLICATE)))
d=cv2.boxFilter(e,-1,(5,5),normalize=False)[2:-2,2:-2]
print("slice contig", t(lambda: np.ascontiguousarray(d)))
dc=np.ascontiguousarray(d)
print("astype64", t(lambda: dc.astype(np.float64)))
keys=dc.astype(np.float64).view(np.int64)
top=np.zeros((rows*W,k),np.int64)
print("concat", t(lambda: np.concatenate([top, keys.reshape(-1,G)],1)))
buf=np.concatenate([top, keys.reshape(-1,G)],1)
print("sort", t(lambda: np.sort(buf,axis=1)))
print("sort f32 31", t(lambda: np.sort(buf.astype(np.float32),axis=1)))
print("per-dy total (x21 x 480/36):", 21*480/rows)
