"""Pictures of the edge refiner on held-out gdsr images: colour, input (bicubic), ground truth, `full`, `trained`
(``from_pretrained("upsample")``), and the error maps, per image, factor and noise level.

    python docs/measurements/refiner/figure.py [--pretrained runs/x/best] [--out docs/measurements/refiner]
"""
import argparse
from pathlib import Path

import cv2
import torch

from torch_depth_sr._data_root import data_root
from torch_depth_sr.datasets.gdsr import gdsr_images
from torch_depth_sr.evaluation.gdsr import _run_model, bicubic, degrade, make_model, rmse
from torch_depth_sr.figures import comparison_figure

CASES = [("Middlebury", "02", 4, 0.0), ("Middlebury", "02", 8, 5.0), ("Lu", "03", 4, 0.0)]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--pretrained", default=None, help="a saved model folder instead of the shipped 'upsample'")
    p.add_argument("--out", default=str(Path(__file__).parent))
    args = p.parse_args()
    torch.set_num_threads(1)
    for dataset, index, scale, noise in CASES:
        img = next(gdsr_images(data_root(), dataset, only=[index]))
        s = degrade(img, scale, noise)
        gt = s["gt"]
        results = {"bicubic": bicubic(s["lr"], gt.shape[-2:])}
        for m in ("full", "trained"):
            results[m] = _run_model(make_model(m, scale, pretrained=args.pretrained), s, "cpu")
        names = {k: f"{k} {rmse(v, gt, dataset):.2f}" for k, v in results.items()}
        path = Path(args.out) / f"{img.name}_x{scale}_n{noise:g}.png"
        comparison_figure(path, s["rgb"][0], results["bicubic"][0, 0], gt[0, 0],
                          torch.ones_like(gt[0, 0]), {names[k]: v[0, 0] for k, v in results.items() if k != "bicubic"},
                          err_max=8.0)
        img = cv2.imread(str(path))  # at 60 % the mosaic stays legible and the file small
        cv2.imwrite(str(path), cv2.resize(img, None, fx=0.6, fy=0.6, interpolation=cv2.INTER_AREA),
                    [cv2.IMWRITE_PNG_COMPRESSION, 9])
        print(path, "  ".join(names.values()))


if __name__ == "__main__":
    main()
