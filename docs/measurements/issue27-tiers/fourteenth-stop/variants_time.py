"""Time candidate settings of the fast tier on 320x240 sensor frames (the DataLoader example's), one thread, every
variant on the same frame in turn; prints the median stage times (ms) and the median ratio of each total to the first
variant's. ROUNDS (default 3; the first is a warm-up). Arguments: NAME={json overrides of fast} | NAME=folder:PATH |
NAME=folder:PATH|{json overrides}."""
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
def variant(spec):
    """'{json overrides of fast}' or 'folder:PATH' or 'folder:PATH|{json overrides}'"""
    src, ov = base, spec
    if spec.startswith("folder:"):
        path, _, ov = spec[7:].partition("|")
        src = DepthRestorer.load(path)
    ov = json.loads(ov or "{}")
    if not ov: return src
    m = DepthRestorer(apply_overrides(src.config, ov))
    sd = {k:v for k,v in src.state_dict().items() if k in m.state_dict()}
    m.load_state_dict(sd, strict=False); return m
V = {k: variant(v) for k,v in [a.split("=",1) for a in sys.argv[1:]]}
acc={k:{} for k in V}
ratios={k:[] for k in V}
first=list(V)[0]
for rnd in range(int(__import__('os').environ.get('ROUNDS','3'))):
  for s in ss:
    tot={}
    for name,m in V.items():  # every variant on the same frame in turn: the machine's swings hit them alike
      with torch.no_grad():
        r=m.restore_with_details(s["depth"][None], s["rgb"][None], timings=True)
      tot[name]=r.info["seconds"]["total"]
      if rnd>0:
        for k,v in r.info["seconds"].items(): acc[name].setdefault(k,[]).append(v)
    if rnd>0:
      for name in V: ratios[name].append(tot[name]/tot[first])
keys=list(acc[first].keys())
print("variant".ljust(12)+"".join(k[:8].rjust(9) for k in keys)+"  ratio to "+first+" (median, quartiles)")
for name in V:
  q=st.quantiles(ratios[name],n=4)
  stages = "".join(f"{st.median(acc[name].get(k, [0])) * 1000:9.1f}" for k in keys)
  print(name.ljust(12) + stages + f"  {st.median(ratios[name]):.3f} ({q[0]:.3f}-{q[2]:.3f})")
