"""Control for docs/measurements/guidance/README.md: the guidance network with every weight frozen but the heads'
biases (heads' weights stay 0), so each map is one learned constant per layer and channel: what the per-pixel maps
add beyond a re-parametrised scalar. Takes the arguments of ``torch-depth-sr train``.

    PYTHONPATH=. python docs/measurements/guidance/bias_only.py --out runs/guided-bias-only --init denoise \
        --model '{"guidance_net": true}' --steps 300 --batch-size 4 --crop 96 --lr 0.03 --val-every 50 \
        --val-size 16 --workers 1 --threads 1
"""
import argparse
import importlib
import sys

from torch_depth_sr.training.cli import _add_arguments, config_from_args

T = importlib.import_module("torch_depth_sr.training.train")
_orig = T._initial_model


def _biases_only(cfg):
    m = _orig(cfg)
    for n, p in m.guidance.named_parameters():
        p.requires_grad_(n.startswith("heads.") and n.endswith(".bias"))
    return m


if __name__ == "__main__":
    T._initial_model = _biases_only
    p = argparse.ArgumentParser()
    _add_arguments(p)
    T.train(config_from_args(p.parse_args(sys.argv[1:])))
