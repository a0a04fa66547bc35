"""Grid search of the JBF baseline on the fitting split (2006 + synthetic), same samples as ``tune.py``.

``python -m torch_depth_sr.evaluation.tune_baselines`` prints every setting's mean RMSE over tracks
``paper`` and ``sensor`` and the best one; the result is frozen in ``methods.JBF_PARAMS``.
"""
from __future__ import annotations

import itertools

import torch

from ..baselines import joint_bilateral_filter
from .tune import fitting_samples

__all__ = ["main"]


def main():
    samples = fitting_samples(160)
    best = None
    for k, ss, sc in itertools.product((5, 7, 9, 11, 15), (1.5, 2.0, 3.0, 5.0), (0.02, 0.05, 0.1, 0.2)):
        errs = []
        for s in samples:
            with torch.no_grad():
                p = joint_bilateral_filter(s["depth"], s["rgb"], (s["depth"] > 0).float(), kernel_size=k,
                                           sigma_space=ss, sigma_color=sc)
            errs.append(float(((p - s["gt"]) ** 2 * s["mask"]).sum() / s["mask"].sum()) ** 0.5)
        score = sum(errs) / len(errs)
        print(f"kernel_size={k} sigma_space={ss} sigma_color={sc}: {score:.4f}", flush=True)
        if best is None or score < best[0]:
            best = (score, dict(kernel_size=k, sigma_space=ss, sigma_color=sc))
    print("best", best)


if __name__ == "__main__":
    main()
