"""Issue 27: accuracy of candidate configurations on the FITTING split (the eleven Middlebury 2006 scenes, full
images) with the protocol of ``torch-depth-sr bench --track paper|sensor`` (its own sample generator and metrics),
and optionally their time at 640x480 against kornia's 9x9 JBF in the same run.

    python docs/measurements/issue27-tiers/fit.py --label L --spec 'config:{"num_layers": 3}' --time

``--spec``: ``preset:NAME``, ``pretrained:NAME``, ``folder:PATH`` (a saved model) or ``config:JSON`` (overrides of
``--base``, default ``preset:full``, the frozen defaults, as ``apply_overrides`` takes them). Each result is appended as one JSON line to
``--out`` (default ``out/issue27/fit.jsonl``). The held-out 2005/2003/2001 scenes are never loaded here.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path

import torch

SCENES_2006 = ("Baby1", "Baby2", "Baby3", "Cloth1", "Cloth2", "Cloth3", "Cloth4", "Midd1", "Midd2", "Wood1", "Wood2")


def build(spec: str, base: str = "preset:default"):
    from torch_depth_sr import DepthRestorer
    from torch_depth_sr.config import TRAINED_PRESETS, apply_overrides

    kind, _, rest = spec.partition(":")
    if kind == "preset":
        return DepthRestorer.from_preset(rest)
    if kind == "pretrained":
        return DepthRestorer.from_pretrained(rest)
    if kind == "folder":
        return DepthRestorer.load(rest)
    if kind == "config":
        b = build(base)
        cfg = apply_overrides(b.config, json.loads(rest))
        m = DepthRestorer(cfg)
        base_kind, _, base_name = base.partition(":")
        if base_kind != "preset" or base_name in TRAINED_PRESETS:  # trained parameters carried over (same shapes)
            m.load_state_dict(b.state_dict())
        return m
    raise SystemExit(f"unknown spec {spec!r}")


def samples(track: str, scenes=SCENES_2006):
    from torch_depth_sr._data_root import data_root
    from torch_depth_sr.evaluation.bench import _samples

    return list(_samples(track, data_root(), list(scenes), None))


def accuracy(model, tracks=("paper", "sensor"), scenes=SCENES_2006) -> dict:
    from torch_depth_sr.evaluation.bench import _metrics

    out = {}
    for track in tracks:
        rows = []
        for rec, s in samples(track, scenes):
            y, rgb = s["depth"][None], s["rgb"][None]
            t0 = time.perf_counter()
            with torch.no_grad():
                pred = model(y, rgb)
            m = _metrics(pred, s, track)
            m["seconds"] = time.perf_counter() - t0
            m["scene"] = rec.name
            rows.append(m)
        out[track] = {k: statistics.fmean(r[k] for r in rows) for k in ("rmse", "mae", "seconds")}
        if track == "sensor":
            out[track]["flying_left"] = statistics.fmean(r["flying_left"] for r in rows if r.get("flying_left") is not None)
        out[track]["per_scene"] = {r["scene"]: (r["rmse"], r["mae"]) for r in rows}
    return out


def timing(model, repeats: int = 3, size=(480, 640)) -> dict:
    """min over rounds of the model's and kornia's 9x9 JBF's seconds, interleaved, after a warm-up round."""
    import kornia

    from torch_depth_sr.evaluation.speed import make_inputs

    y, rgb, _ = make_inputs(*size, 1)
    tm, tk = [], []
    with torch.no_grad():
        for rep in range(repeats + 1):
            t0 = time.perf_counter()
            kornia.filters.joint_bilateral_blur(y, rgb, (9, 9), 0.1, (3.0, 3.0))
            t1 = time.perf_counter()
            model(y, rgb)
            t2 = time.perf_counter()
            if rep:
                tk.append(t1 - t0)
                tm.append(t2 - t1)
    return {"seconds": min(tm), "kornia": min(tk), "ratio": min(tm) / min(tk), "load": os.getloadavg()[0]}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--label", required=True)
    p.add_argument("--spec", required=True)
    p.add_argument("--base", default="preset:full")
    p.add_argument("--tracks", nargs="*", default=["paper", "sensor"])
    p.add_argument("--time", action="store_true")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--out", default="out/issue27/fit.jsonl")
    a = p.parse_args()
    torch.set_num_threads(a.threads)
    model = build(a.spec, a.base)
    row = {"label": a.label, "spec": a.spec, "base": a.base}
    if a.tracks:
        row["accuracy"] = accuracy(model, a.tracks)
    if a.time:
        row["timing"] = timing(model, a.repeats)
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    with open(a.out, "a") as f:
        f.write(json.dumps(row) + "\n")
    cells = [f"{t} {v['rmse']:.4f}/{v['mae']:.4f}" for t, v in row.get("accuracy", {}).items()]
    if "timing" in row:
        cells.append(f"{row['timing']['seconds']:.3f} s = {row['timing']['ratio']:.1f}x JBF "
                     f"(load {row['timing']['load']:.1f})")
    print(f"{a.label:30s} " + "  ".join(cells), flush=True)


if __name__ == "__main__":
    main()
