"""Grid search of the rolling guidance filter baseline on the fitting split (full 2006 images), per track.

``python -m torch_depth_sr.evaluation.tune_rgf`` prints every setting's mean RMSE and MAE over the eleven
Middlebury 2006 scenes for tracks ``paper`` and ``sensor`` separately and the best setting of each by RMSE;
the results are frozen in ``methods.RGF_PARAMS``. No 2005/2003/2001 scene is read. Per track, because a
self-guided bilateral keeps flying pixels and impulses (they guide themselves), so the two tracks want
opposite settings and a common one would be poor on both.
"""
from __future__ import annotations

import itertools

import torch
from tqdm import tqdm

from ..baselines import rolling_guidance_filter
from .tune import fitting_samples

__all__ = ["main"]


def main() -> None:
    samples = fitting_samples(None, n_synthetic=0)
    grid = list(itertools.product((2.0, 3.0, 5.0), (3.0, 5.0, 7.0, 10.0, 20.0), (2, 3, 4)))
    best: dict = {}
    for ss, sc, it in tqdm(grid, desc="rgf grid"):
        errs: dict = {}
        for s in samples:
            with torch.no_grad():
                p = rolling_guidance_filter(s["depth"], (s["depth"] > 0).float(), ss, sc, it)
            m = s["mask"]
            e = errs.setdefault(s["track"], ([], []))
            e[0].append(float(((p - s["gt"]) ** 2 * m).sum() / m.sum()) ** 0.5)
            e[1].append(float(((p - s["gt"]).abs() * m).sum() / m.sum()))
        line = []
        for track, (rmse, mae) in errs.items():
            score = sum(rmse) / len(rmse)
            line.append(f"{track} RMSE {score:.4f} MAE {sum(mae) / len(mae):.4f}")
            if track not in best or score < best[track][0]:
                best[track] = (score, dict(sigma_space=ss, sigma_color=sc, iterations=it))
        tqdm.write(f"sigma_space={ss} sigma_color={sc} iterations={it}: " + "  ".join(line))
    for track, b in best.items():
        print("best", track, b)


if __name__ == "__main__":
    main()
