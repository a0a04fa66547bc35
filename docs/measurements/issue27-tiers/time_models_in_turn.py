"""Saved models and kornia's 9x9 JBF timed in turn in one process at 640x480 (2 threads; ``--rounds`` rounds, each
figure the median; a synthetic frame with noise sigma 3), and each model's median over kornia's. Written to compare two
refiners of one tier where separate speed-track runs cannot (kornia's time moves 2x between runs).

    python docs/measurements/issue27-tiers/time_models_in_turn.py --rounds 5 r16=runs/default-r16 r24=runs/default-r24/best

Used in the eleventh stop (``r16=runs/default-warm/best r32=runs/default-r32/best``, three rounds:
``eleventh-stop/time_r16_r32.txt``) and the twelfth (``twelfth-stop/time_r16_r24.txt``).
"""
import argparse
import statistics
import time

import kornia
import torch

from torch_depth_sr import DepthRestorer
from torch_depth_sr.datasets.synthetic import make_scene


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("models", nargs="+", metavar="LABEL=FOLDER", help="a label and the folder DepthRestorer.save wrote")
    p.add_argument("--rounds", type=int, default=3)
    a = p.parse_args()
    torch.set_num_threads(2)
    s = make_scene(480, 640, seed=0)
    d = (s["gt"] + 3 * torch.randn(s["gt"].shape, generator=torch.Generator().manual_seed(0)))[None].float()
    rgb = s["rgb"][None].float()
    models = {label: DepthRestorer.load(folder).eval() for label, folder in (m.split("=", 1) for m in a.models)}
    runs = dict(models, kornia=lambda x, g: kornia.filters.joint_bilateral_blur(x, g, (9, 9), 0.1, (1.5, 1.5)))
    times = {k: [] for k in runs}
    with torch.no_grad():
        for run in runs.values():  # warm-up
            run(d, rgb)
        for _ in range(a.rounds):
            for k, run in runs.items():
                t = time.perf_counter()
                run(d, rgb)
                times[k].append(time.perf_counter() - t)
    for k, v in times.items():
        print(k, " ".join(f"{x:.3f}" for x in v), "median", f"{statistics.median(v):.3f}")
    kn = statistics.median(times["kornia"])
    for k in models:
        print(k, f"{statistics.median(times[k]) / kn:.1f}x kornia")


if __name__ == "__main__":
    main()
