import time, torch, statistics as st, json, sys
torch.set_num_threads(1)
from torch_depth_sr import DepthRestorer
from torch_depth_sr.config import apply_overrides
from torch_depth_sr.datasets.synthetic import SyntheticScenes
from torch_depth_sr.degradations import SensorDegradation
from torch_depth_sr.warmup import warmup
warmup(dtypes=(torch.float32,))
ds = SyntheticScenes(n=16, size=(240,320)); deg=SensorDegradation(seed=0)
ss=[deg(ds[i]) for i in range(6)]
base = DepthRestorer.from_preset('fast')
def variant(ov):
    if not ov: return base
    m = DepthRestorer(apply_overrides(base.config, ov))
    sd = {k:v for k,v in base.state_dict().items() if k in m.state_dict()}
    m.load_state_dict(sd, strict=False); return m
V = {k: variant(json.loads(v)) for k,v in [a.split("=",1) for a in sys.argv[1:]]}
acc={k:{} for k in V}
for rnd in range(3):
  for name,m in V.items():
    for s in ss:
      with torch.no_grad():
        r=m.restore_with_details(s["depth"][None], s["rgb"][None], timings=True)
      if rnd>0:
        for k,v in r.info["seconds"].items(): acc[name].setdefault(k,[]).append(v)
keys=list(acc[list(V)[0]].keys())
print("variant".ljust(12)+"".join(k[:8].rjust(9) for k in keys))
for name in V:
  print(name.ljust(12)+"".join(f"{st.median(acc[name].get(k,[0]))*1000:9.1f}" for k in keys))
