import time, numpy as np, torch
def t(f,n=3):
    f(); t0=time.perf_counter()
    for _ in range(n): f()
    return (time.perf_counter()-t0)/n*1e3
n=20480
for dt in (np.int64, np.float32):
    a=(np.random.rand(n,441)*1e6).astype(dt)
    print(dt, "partition 441", t(lambda: np.partition(a,9,axis=1)), "ms per 20480 rows")
    b=(np.random.rand(n,31)*1e6).astype(dt)
    print(dt, "partition 31", t(lambda: np.partition(b,9,axis=1)))
    print(dt, "sort 31", t(lambda: np.sort(b,axis=1)))
a=torch.rand(n,441)
print("torch topk 441", t(lambda: torch.topk(a,10,dim=1,largest=False)))
b=torch.rand(n,31)
print("torch topk 31", t(lambda: torch.topk(b,10,dim=1,largest=False)))
print("torch sort 31", t(lambda: torch.sort(b,dim=1)))
bi=(torch.rand(n,31)*1e6).long()
print("torch sort 31 int64", t(lambda: torch.sort(bi,dim=1)))
ai=(torch.rand(n,441)*1e6).long()
print("torch kthvalue 441 int64", t(lambda: torch.kthvalue(ai,10,dim=1)))
