"""The do-no-harm checks of tests/test_do_no_harm.py for each model, with their figures: a clean integer map with a
hole (largest change at measured pixels), a lightly noisy synthetic map (sigma 0.3, 1.0) and the Art crop of the test
(clean, then sigma 0.3 / 0.5 / 1.0): restored RMSE / the input's. Arguments: preset names, folder:PATH, or NAME-noref
(the preset without its edge refiner).

    python docs/measurements/issue27-tiers/tier-refiners/near_clean_tiers.py fast default best full
"""
"""Do-no-harm checks for each tier: clean synthetic, lightly noisy synthetic, Art crop at sigma 0.3/0.5/1."""
import sys
import numpy as np, torch, cv2
from torch_depth_sr import DepthRestorer, restore_depth
from torch_depth_sr._data_root import require_data_root
from torch_depth_sr.datasets.synthetic import make_scene
torch.set_num_threads(1)
def clean_scene(h=96, w=128, seed=0):
    s = make_scene(h, w, seed=seed)
    depth = s["gt"][0].round().clamp(1, 255).numpy().astype(np.uint8)
    rgb = (s["rgb"].permute(1, 2, 0).numpy() * 255).round().astype(np.uint8)
    return depth, rgb
def rmse(a, b, m):
    return float(np.sqrt(((a.astype(np.float64) - b.astype(np.float64))[m] ** 2).mean()))
specs = sys.argv[1:] or ["fast", "default", "best"]
art = require_data_root("middlebury2005") / "middlebury2005" / "Art"
adepth = cv2.imread(str(art / "disp1.png"), cv2.IMREAD_UNCHANGED)[100:220, 150:310]
argb = cv2.imread(str(art / "view1.png"))[100:220, 150:310, ::-1].copy()
for spec in specs:
    if spec.endswith("-noref"):
        base = DepthRestorer.from_preset(spec[:-6])
        model = DepthRestorer(base.config.replace(refiner=None))
        missing = model.load_state_dict({k: v for k, v in base.state_dict().items() if not k.startswith("refiner.")})
    elif spec.startswith("folder:"):
        model = DepthRestorer.load(spec[7:])
    else:
        model = DepthRestorer.from_preset(spec)
    model.eval()
    out = []
    d, rgb = clean_scene()
    d[40:46, 50:60] = 0
    r = restore_depth(d, rgb, model=model)
    m = d > 0
    out.append(f"clean-int maxdiff {np.abs(r[m].astype(int) - d[m].astype(int)).max()}")
    d, rgb = clean_scene(seed=2)
    rng = np.random.default_rng(0)
    for sigma in (0.3, 1.0):
        noisy = (d + sigma * rng.standard_normal(d.shape)).astype(np.float32)
        o = restore_depth(noisy, rgb, model=model)
        m = d > 0
        out.append(f"syn s{sigma} {rmse(o, d, m):.4f}/{rmse(noisy, d, m):.4f}")
    oa = restore_depth(adepth, argb, model=model)
    out.append(f"art-clean maxdiff {np.abs(oa[adepth>0].astype(int) - adepth[adepth>0].astype(int)).max()}")
    for sigma in (0.3, 0.5, 1.0):
        noisy = (adepth + sigma * np.random.default_rng(0).standard_normal(adepth.shape)).astype(np.float32)
        noisy[adepth == 0] = 0
        m = adepth > 0
        restored = restore_depth(noisy, argb, model=model)
        out.append(f"art s{sigma} {rmse(restored, adepth, m):.4f}/{rmse(noisy, adepth, m):.4f}")
    print(spec, " | ".join(out), flush=True)
