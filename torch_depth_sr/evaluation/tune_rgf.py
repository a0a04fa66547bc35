"""Grid search of the rolling guidance filter baseline on the fitting split (full 2006 images, paper + sensor).

``python -m torch_depth_sr.evaluation.tune_rgf`` prints every setting's mean RMSE and MAE over the eleven
Middlebury 2006 scenes of tracks ``paper`` and ``sensor`` and the best one by RMSE; the result is frozen in
``methods.RGF_PARAMS``. No 2005/2003/2001 scene is read.
"""
from __future__ import annotations

import itertools

import torch
from tqdm import tqdm

from ..baselines import rolling_guidance_filter
from .tune import fitting_samples


def main():
    samples = fitting_samples(None, n_synthetic=0)
    best = None
    grid = list(itertools.product((2.0, 3.0, 5.0), (3.0, 5.0, 7.0, 10.0), (3, 4, 6)))
    for ss, sc, it in tqdm(grid, desc="rgf grid"):
        rmse, mae = [], []
        for s in samples:
            with torch.no_grad():
                p = rolling_guidance_filter(s["depth"], (s["depth"] > 0).float(), ss, sc, it)
            m = s["mask"]
            rmse.append(float(((p - s["gt"]) ** 2 * m).sum() / m.sum()) ** 0.5)
            mae.append(float(((p - s["gt"]).abs() * m).sum() / m.sum()))
        score = sum(rmse) / len(rmse)
        tqdm.write(f"sigma_space={ss} sigma_color={sc} iterations={it}: RMSE {score:.4f}  MAE {sum(mae) / len(mae):.4f}")
        if best is None or score < best[0]:
            best = (score, dict(sigma_space=ss, sigma_color=sc, iterations=it))
    print("best", best)


if __name__ == "__main__":
    main()
