"""Streams made from one Middlebury 2006 scene (the FITTING split) for the issue-28 measurements of this folder
(``static_2006.py``, ``stream_2006_frames.py``, ``fit_stream_2006.py``, ``layers_2006.py``): frame t is the ``paper``
or ``sensor`` track's degradation of the scene with seed t, optionally with a near square that enters at frame 10
and moves 4 px per frame. The held-out 2005/2003/2001 scenes are never loaded here."""
from __future__ import annotations

import argparse

import torch

from torch_depth_sr._data_root import data_root
from torch_depth_sr.datasets.discover import find_scenes
from torch_depth_sr.degradations import make_degradation

SCENES = ("Baby1", "Cloth1", "Midd1", "Wood1")
MOVER_FROM = 10  # the frame the square enters


def arguments(doc: str, frames: int, threads: int = 2) -> argparse.ArgumentParser:
    """The options every script of these streams takes: ``--frames``, ``--scenes``, ``--threads``."""
    p = argparse.ArgumentParser(description=doc)
    p.add_argument("--frames", type=int, default=frames)
    p.add_argument("--scenes", nargs="+", default=list(SCENES))
    p.add_argument("--threads", type=int, default=threads)
    return p


def scenes(track: str, names) -> list:
    """The scene records of ``track`` named in ``names`` (the data root's order)."""
    return [r for r in find_scenes(data_root(), track) if r.name in names]


def degraded_frames(scene: dict, track: str, count: int, mover: bool = False) -> list:
    """``count`` frames of ``scene``: the track's degradation with seed t (depth clamped at 0, as the bench does),
    with the square from frame ``MOVER_FROM`` on when ``mover``."""
    h, w = scene["gt"].shape[-2:]
    size = min(h, w) // 5
    out = []
    for t in range(count):
        s = {k: (v.clone() if torch.is_tensor(v) else v) for k, v in scene.items()}
        if mover and t >= MOVER_FROM:
            r0, c0 = h // 3, w // 4 + 4 * (t - MOVER_FROM)
            s["gt"][..., r0:r0 + size, c0:c0 + size] = s["gt"].max() * 1.1
            s["rgb"][..., r0:r0 + size, c0:c0 + size] = torch.tensor([0.1, 0.8, 0.2]).view(3, 1, 1)
        d = make_degradation(track, seed=t)(s)
        d["depth"] = d["depth"].clamp_min(0)
        out.append(d)
    return out
