"""Build an init folder: a pretrained model cut to N layers (layers/heads kept by index), config overrides applied."""
import json, sys
from torch_depth_sr import DepthRestorer
from torch_depth_sr.config import apply_overrides

src, out, keep, over = sys.argv[1], sys.argv[2], json.loads(sys.argv[3]), json.loads(sys.argv[4])
base = DepthRestorer.from_pretrained(src) if "/" not in src else DepthRestorer.load(src)
over = dict(over, num_layers=len(keep))
cfg = apply_overrides(base.config, over)
m = DepthRestorer(cfg)
sd = base.state_dict()
new = {}
for k, v in m.state_dict().items():
    parts = k.split(".")
    if parts[0] == "layers":
        parts[1] = str(keep[int(parts[1])])
    if parts[:2] == ["guidance", "heads"]:
        parts[2] = str(keep[int(parts[2])])
    new[k] = sd[".".join(parts)]
m.load_state_dict(new)
m.save(out)
print(out, cfg.num_layers)
