"""Grid search of the ``jbf`` denoising baseline on the fitting split (full 2006 images), per track.

``python -m torch_depth_sr.evaluation.tune_jbf`` prints every setting's mean RMSE and MAE over the eleven
Middlebury 2006 scenes and the best setting of each track by mean RMSE; the results are frozen in
``methods.JBF_PARAMS``. No 2005/2003/2001 scene is read. The structure is ``tune_rgf``'s; the grids differ
per track: on ``paper`` (Gaussian noise) a single masked JBF pass or an iterated one, L1 or L2 colour distance;
on ``sensor`` (flying pixels, impulses) iterated passes with median-based outlier rejection
(:func:`~torch_depth_sr.baselines.jbf.jbf_denoise`). ``--scenes`` restricts the 2006 scenes (for development).
"""
from __future__ import annotations

import argparse
import itertools
from typing import Optional, Sequence

import torch
from tqdm import tqdm

from ..baselines.jbf import jbf_denoise
from .tune import fitting_samples

__all__ = ["GRIDS", "main"]

# (sigma_space, sigma_color in 0-255 grey levels, iterations, reject, color_distance_type)
GRIDS = {
    "paper": list(itertools.product((1.0, 1.5, 2.0, 2.5, 3.0), (5.0, 10.0, 15.0, 20.0, 30.0), (1, 2), (None,),
                                    ("l1", "l2"))),
    "sensor": list(itertools.product((1.5, 2.0), (10.0, 20.0), (2, 3), (10.0, 15.0, 20.0), ("l1",)))
    # the optimum of that grid lay on its edge (σc 20, reject 20): extended there
    + [(2.0, 30.0, 2, 20.0, "l1"), (2.0, 40.0, 2, 20.0, "l1"), (2.0, 20.0, 2, 30.0, "l1"), (2.0, 30.0, 2, 30.0, "l1"),
       (2.5, 20.0, 2, 20.0, "l1"), (3.0, 20.0, 2, 20.0, "l1")],
}


def _errors(samples, params: dict) -> tuple[float, float]:
    rmse, mae = [], []
    for s in samples:
        with torch.no_grad():
            p = jbf_denoise(s["depth"], s["rgb"], (s["depth"] > 0).float(), **params)
        m = s["mask"]
        rmse.append(float(((p - s["gt"]) ** 2 * m).sum() / m.sum()) ** 0.5)
        mae.append(float(((p - s["gt"]).abs() * m).sum() / m.sum()))
    return sum(rmse) / len(rmse), sum(mae) / len(mae)


def main(argv: Optional[Sequence[str]] = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--tracks", nargs="*", default=list(GRIDS))
    ap.add_argument("--scenes", nargs="*", default=None, help="restrict to these 2006 scenes")
    args = ap.parse_args(argv)
    samples = fitting_samples(None, n_synthetic=0, tracks=tuple(args.tracks))
    if args.scenes:
        wanted = {s.lower() for s in args.scenes}
        samples = [s for s in samples if s["name"].lower() in wanted]
    for track in args.tracks:
        mine = [s for s in samples if s["track"] == track]
        best = None
        for ss, sc, it, rej, dist in tqdm(GRIDS[track], desc=f"jbf grid {track}"):
            params = dict(sigma_space=ss, sigma_color=sc, iterations=it, reject=rej, color_distance_type=dist)
            rmse, mae = _errors(mine, params)
            tqdm.write(f"{track} {params}: RMSE {rmse:.4f} MAE {mae:.4f}")
            if best is None or rmse < best[0]:
                best = (rmse, mae, params)
        print(f"best {track} ({len(mine)} scenes): RMSE {best[0]:.4f} MAE {best[1]:.4f} {best[2]}", flush=True)


if __name__ == "__main__":
    main()
