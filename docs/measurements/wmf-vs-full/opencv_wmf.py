"""OpenCV's ximgproc.weightedMedianFilter (guided by the colour image) on the `sensor` bench inputs.

Run with an environment that has opencv-contrib-python-headless (see README); reads $WMF_CHECK_DIR (default
/tmp/wmf-check, written by save_inputs.py). Grid: radius r x sigma x weight type x source dtype (float32 /
rounded uint8) x hole handling:
* "mask": holes (input 0) get mask 0, so they do not vote; pixels the filter still leaves at 0 (no measured
  pixel in the window) are Telea-inpainted;
* "telea": holes are Telea-inpainted first (as opencv_jbf.py does), then filtered without a mask.
Metrics as torch_depth_sr.metrics.evaluate: RMSE / MAE over GT-known pixels, flying_left = share of the
flying+impulse pixels (the degradation's masks, & known) more than 3 grey levels off the GT; mean over scenes.
Selects on the eleven 2006 scenes by flying_left (ties: RMSE); writes grid.tsv and prints the table rows.

The filter quantises a 3-channel guide with cv::kmeans, which draws from OpenCV's global RNG: without a fixed
seed two calls on the same input differ (about 12 % of the pixels of Baby1, by up to 60 grey levels). Every call
here therefore starts from cv2.setRNGSeed(SEED) (SEED = 0); the fitted setting is also run with seeds 0-4.
"""
import itertools
import os

import cv2
import numpy as np

cv2.setNumThreads(1)  # the machine is shared
D = os.environ.get("WMF_CHECK_DIR", "/tmp/wmf-check") + "/"
HELD_OUT = ["Art", "Books", "Dolls", "Laundry", "Moebius", "Reindeer", "Cones", "Teddy", "Tsukuba", "Venus"]
ALL = sorted({f[: -len("_gt.npy")] for f in os.listdir(D) if f.endswith("_gt.npy")})
FIT = [s for s in ALL if s not in HELD_OUT]
WT = {"EXP": cv2.ximgproc.WMF_EXP, "IV1": cv2.ximgproc.WMF_IV1, "IV2": cv2.ximgproc.WMF_IV2,
      "COS": cv2.ximgproc.WMF_COS, "JAC": cv2.ximgproc.WMF_JAC, "OFF": cv2.ximgproc.WMF_OFF}
GRID = [s for s in itertools.product((2, 3, 5, 7), (10.0, 25.5, 50.0), WT, ("f32", "u8"), ("mask", "telea"))
        if not (s[2] == "OFF" and s[1] != 25.5)]  # OFF = unweighted median: sigma unused
SEED = 0
cache = {}


def load(n):
    if n not in cache:
        y = np.load(f"{D}{n}_y.npy")
        holes = (y <= 0).astype(np.uint8)
        rgb = np.clip(np.round(np.load(f"{D}{n}_rgb.npy")), 0, 255).astype(np.uint8)
        cache[n] = dict(y=y, holes=holes, telea=cv2.inpaint(y, holes, 3, cv2.INPAINT_TELEA), joint=rgb,
                        gt=np.load(f"{D}{n}_gt.npy"), known=np.load(f"{D}{n}_known.npy"),
                        out=np.load(f"{D}{n}_out.npy"))
    return cache[n]


def wmf(d, r, sigma, wt, dtype, holes):
    src = d["telea"] if holes == "telea" else d["y"]
    if dtype == "u8":
        src = np.clip(np.round(src), 0, 255).astype(np.uint8)
    kw = dict(sigma=sigma, weightType=WT[wt])
    if holes == "mask":
        kw["mask"] = 1 - d["holes"]
    cv2.setRNGSeed(SEED)
    out = cv2.ximgproc.weightedMedianFilter(d["joint"], src, r, **kw).astype(np.float32)
    if holes == "mask" and (out <= 0).any():
        out = cv2.inpaint(out, (out <= 0).astype(np.uint8), 3, cv2.INPAINT_TELEA)
    return out


def scene_metrics(n, setting):
    d = load(n)
    e = (wmf(d, *setting) - d["gt"]).astype(np.float64)
    k = e[d["known"]]
    return np.sqrt((k ** 2).mean()), np.abs(k).mean(), (np.abs(e[d["out"]]) > 3).mean()


def mean_metrics(names, setting):
    return np.array([scene_metrics(n, setting) for n in names]).mean(0)


if __name__ == "__main__":
    rows = []
    with open("grid.tsv", "w") as f:
        f.write("r\tsigma\tweight\tdtype\tholes\tfit2006_rmse\tfit2006_mae\tfit2006_flying_left\n")
        for s in GRID:
            m = mean_metrics(FIT, s)
            rows.append((s, m))
            f.write("\t".join(map(str, s)) + "\t" + "\t".join(f"{v:.4f}" for v in m) + "\n")
            f.flush()
    best_fl = min(rows, key=lambda t: (round(t[1][2], 4), t[1][0]))[0]
    best_rmse = min(rows, key=lambda t: t[1][0])[0]
    default = (3, 25.5, "EXP", "f32", "mask")  # not fitted: OpenCV's default sigma/weight at r = 3
    for label, s in (("fitted by flying_left", best_fl), ("fitted by RMSE", best_rmse), ("default", default)):
        print(label, s)
        for sub, names in (("2006 (11)", FIT), ("all 21", ALL), ("held out (10)", HELD_OUT)):
            r, a, fl = mean_metrics(names, s)
            print(f"  {sub:14s} RMSE {r:.3f}  MAE {a:.3f}  flying+impulse left {100 * fl:.1f} %")
    print("fitted by flying_left, RNG seeds 0-4 (min-max)")
    per_seed = {}
    for SEED in range(5):
        per_seed[SEED] = {sub: mean_metrics(names, best_fl) for sub, names in
                          (("2006 (11)", FIT), ("all 21", ALL), ("held out (10)", HELD_OUT))}
    for sub in ("2006 (11)", "all 21", "held out (10)"):
        v = np.array([per_seed[k][sub] for k in per_seed])
        print(f"  {sub:14s} RMSE {v[:, 0].min():.3f}-{v[:, 0].max():.3f}  MAE {v[:, 1].min():.3f}-{v[:, 1].max():.3f}"
              f"  flying+impulse left {100 * v[:, 2].min():.1f}-{100 * v[:, 2].max():.1f} %")
