"""Issue 27: where the time of a forward goes, stage by stage, at 640x480, with kornia's 9x9 JBF in the same run.

    OMP_NUM_THREADS=2 python docs/measurements/issue27-tiers/stage_table.py --repeats 3 \
        --models preset:default preset:fast pretrained:denoise-refined --input synthetic sensor

Each model runs ``restore_with_details(..., timings=True)`` (the stages the model times itself: block matching,
nonlocal terms, singular test, CG, the edge steps, the refiner); forward hooks time the initial stage, whose own
block matching (and α⁰) is subtracted to give x⁰'s fill; "observe" is the wall time outside the model's own total
(input checks, the scale policy / noise estimate); "layers, other" = total − every timed stage (shrinkage, Dx,
guidance network, gate). kornia's ``joint_bilateral_blur`` (9x9, σ_color 0.1, σ_space 3, as ``bench --track
speed``) runs interleaved with the models, so every ratio is taken within one round; each figure is the minimum
over ``--repeats`` rounds after one warm-up round (the machine is shared: the minimum is the least disturbed).

Inputs: ``synthetic`` = what ``bench --track speed`` times (``evaluation.speed.make_inputs``: a procedural scene, σ = 5
noise, about 5 % holes; the singular gate finds it clean, so the edge steps do not run); ``sensor`` = the same scene
degraded by the ``sensor`` protocol (flying pixels, impulses, holes; the gate finds outliers and the edge steps run).
Timing only: neither input is a benchmark scene.
"""
from __future__ import annotations

import argparse
import json
import os
import time

import torch

from torch_depth_sr import DepthRestorer

STAGES = ("observe", "x0", "block_matching", "nonlocal", "singular", "cg", "layers_other", "snap", "refine")


def make_input(kind: str, h: int = 480, w: int = 640):
    from torch_depth_sr.evaluation.speed import make_inputs

    if kind == "synthetic":
        y, rgb, _ = make_inputs(h, w, 1)
        return y, rgb
    from torch_depth_sr.datasets.synthetic import make_scene
    from torch_depth_sr.degradations import SensorDegradation

    s = SensorDegradation(seed=0)(make_scene(h, w, seed=0))
    return s["depth"][None].clamp_min(0), s["rgb"][None]


def load(spec: str) -> DepthRestorer:
    kind, _, name = spec.partition(":")
    if kind == "preset":
        return DepthRestorer.from_preset(name)
    if kind == "pretrained":
        return DepthRestorer.from_pretrained(name)
    if kind == "folder":  # a saved model (DepthRestorer.save)
        return DepthRestorer.load(name)
    if kind == "config":  # config:<json of overrides of the defaults>
        from torch_depth_sr.config import RestorerConfig, apply_overrides

        return DepthRestorer(apply_overrides(RestorerConfig(), json.loads(name)))
    raise SystemExit(f"unknown model spec {spec!r} (preset:NAME, pretrained:NAME, folder:PATH, config:JSON)")


class InitTimer:
    """Forward hooks on the model's initial stages: their wall time per forward."""

    def __init__(self, model: DepthRestorer):
        self.seconds = 0.0
        for m in model.init.values():
            m.register_forward_pre_hook(self._pre)
            m.register_forward_hook(self._post)

    def _pre(self, *_):
        self._t0 = time.perf_counter()

    def _post(self, *_):
        self.seconds += time.perf_counter() - self._t0


def timed_forward(model: DepthRestorer, timer: InitTimer, y, rgb) -> dict:
    timer.seconds = 0.0
    t0 = time.perf_counter()
    r = model.restore_with_details(y, rgb, timings=True)
    wall = time.perf_counter() - t0
    sec = dict(r.info["seconds"])
    out = {k: sec.get(k, 0.0) for k in ("block_matching", "nonlocal", "singular", "cg", "snap", "refine")}
    out["init"] = timer.seconds
    out["init_bm"] = sec.get("_init_bm", 0.0)
    out["total"] = wall
    out["observe"] = wall - sec["total"]
    return out


def install_init_bm_probe(model: DepthRestorer) -> None:
    """Record the block matching done inside the initial stage separately (``_init_bm``): wrap the matcher's
    ``forward`` (the exact search on x⁰; the layers' re-matches go through ``rematch``)."""
    bm = model.block_matcher
    inner = bm.forward

    def forward(x, obs, q):
        t0 = time.perf_counter()
        res = inner(x, obs, q)
        if obs.log.timings is not None:
            obs.log.timings["_init_bm"] = obs.log.timings.get("_init_bm", 0.0) + time.perf_counter() - t0
        return res

    bm.forward = forward


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--models", nargs="+", default=["preset:default", "preset:fast", "pretrained:denoise-refined"])
    p.add_argument("--input", nargs="+", default=["synthetic"], choices=["synthetic", "sensor"])
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--size", type=int, nargs=2, default=(480, 640))
    p.add_argument("--json", default=None)
    a = p.parse_args()
    torch.set_num_threads(a.threads)
    import kornia

    models = {m: load(m) for m in a.models}
    timers = {m: InitTimer(models[m]) for m in a.models}
    for m in models.values():
        install_init_bm_probe(m)
    results = {}
    for kind in a.input:
        y, rgb = make_input(kind, *a.size)
        rounds = []
        with torch.no_grad():
            for rep in range(a.repeats + 1):  # round 0 warms up
                row = {}
                t0 = time.perf_counter()
                kornia.filters.joint_bilateral_blur(y, rgb, (9, 9), 0.1, (3.0, 3.0))
                row["kornia-jbf9"] = {"total": time.perf_counter() - t0}
                for name, model in models.items():
                    row[name] = timed_forward(model, timers[name], y, rgb)
                if rep:
                    rounds.append(row)
        best = {}
        for name in ["kornia-jbf9", *a.models]:
            rs = [r[name] for r in rounds]
            b = min(rs, key=lambda r: r["total"])  # the least disturbed round of this method
            best[name] = b
        k = best["kornia-jbf9"]["total"]
        print(f"\ninput {kind} {a.size[1]}x{a.size[0]}, {a.threads} threads, min of {a.repeats} rounds; "
              f"kornia 9x9 JBF {k * 1000:.1f} ms; load {os.getloadavg()[0]:.2f}")
        head = "| stage | " + " | ".join(a.models) + " |"
        print(head)
        print("|---" * (len(a.models) + 1) + "|")
        rows = {}
        for name in a.models:
            b = best[name]
            st = {"observe": b["observe"], "x0": b["init"] - b["init_bm"], "block_matching": b["block_matching"],
                  "nonlocal": b["nonlocal"], "singular": b["singular"], "cg": b["cg"], "snap": b["snap"],
                  "refine": b["refine"]}
            st["layers_other"] = b["total"] - sum(st.values())
            st["total"] = b["total"]
            rows[name] = st
        for s in (*STAGES, "total"):
            cells = []
            for name in a.models:
                v = rows[name][s]
                cells.append(f"{v:.3f} s ({v / rows[name]['total'] * 100:.0f} %)" if s != "total" else
                             f"**{v:.2f} s = {v / k:.0f}x JBF**")
            print(f"| {s} | " + " | ".join(cells) + " |")
        results[kind] = {"kornia_seconds": k, "stages": rows, "rounds": rounds, "loadavg_end": os.getloadavg()}
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"threads": a.threads, "size": a.size, "repeats": a.repeats, "results": results}, f, indent=1)


if __name__ == "__main__":
    main()
