"""Time of the frozen model for a few (k, search window) settings, interleaved (issue 11's k = 40 default).

    OMP_NUM_THREADS=1 python docs/measurements/k-speed/time_k.py

One thread, a synthetic 370×465 scene with σ = 5 noise; each setting run twice in turn after a warm-up, best of
two printed. Compare the rows of one run only: this shared machine's speed varies between runs.
"""
import time

import torch

from torch_depth_sr import DepthRestorer
from torch_depth_sr.config import RestorerConfig, apply_overrides
from torch_depth_sr.datasets.synthetic import make_scene

SETTINGS = {  # version-1 names (config.apply_overrides converts them)
    "former defaults (k 10 in 21x21)": dict(k=10, search_window=21, nl_value_weight_clean=0.0),
    "k 20 in 21x21": dict(k=20, search_window=21),
    "k 20 in 15x15": dict(k=20, search_window=15),
    "k 30 in 15x15": dict(k=30, search_window=15),
    "k 40 in 15x15 (default)": {},
}


def main() -> None:
    torch.set_num_threads(1)
    s = make_scene(370, 465, seed=3)
    y = (s["gt"] + 5 * torch.randn(s["gt"].shape, generator=torch.Generator().manual_seed(0))).clamp_min(1)[None]
    rgb = s["rgb"][None]
    models = {name: DepthRestorer(apply_overrides(RestorerConfig(), c)) for name, c in SETTINGS.items()}
    times: dict = {name: [] for name in models}
    with torch.no_grad():
        for m in models.values():  # warm-up: numba compiles on first use
            m(y[..., :64, :64], rgb[..., :64, :64])
        for _ in range(2):
            for name, m in models.items():
                t = time.perf_counter()
                m(y, rgb)
                times[name].append(time.perf_counter() - t)
    for name, t in times.items():
        print(f"{name:34s} {min(t):.2f} s")


if __name__ == "__main__":
    main()
