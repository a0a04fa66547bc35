"""Issue 28, twenty-fourth stop: variants of the stream tried against the trails and the holes' fill, each as a patch
of this process (nothing here is shipped), on fitting scenes, each scene against frame-by-frame restoration.

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/twenty-fourth-stop/tried_variants.py --set tuning \
        --size 480x640 --variants shipped whole near4 near8
    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/twenty-fourth-stop/tried_variants.py --set fit \
        --size 120x160 --variants shipped near4 near8

Variants:

* ``shipped`` — the stream as it is;
* ``whole`` — the later layers on the whole frame instead of crops around the fresh pixels (the values pasted at the
  same pixels: are the crops' own CG step sizes behind the longer trails at 480×640?);
* ``nearR`` — no measurement is held out as a first departure from its run within R px of a changed pixel
  (:func:`~torch_depth_sr.stream.runs.join_runs`' torch path with that one condition added: at a mover's edge a
  background measurement was held out for a frame, traced on seed 204 at the twenty-third stop);
* ``unpulledR`` — no temporal prior within R px of a changed pixel;
* ``fill:V`` — the twenty-second stop's variant ``V`` of x⁰'s fill (``tried_fill_from_raw.py``: the fill fed the
  readings the stream holds out or drops), run here at another size.

``--set``: ``tuning`` (the three tuning sequences) or ``fit`` (the 45 fitting scenes of ``setting_synthetic.py``). Per
scene RMSE, flicker and trail divided by frame-by-frame restoration's, then the mean and the count of scenes missing
issue 28's targets.
"""
from __future__ import annotations

import argparse
import math
import sys
from multiprocessing import Pool
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "nineteenth-stop"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "twenty-second-stop"))
from fresh_seeds import KEYS, LIMITS, restored_frames  # noqa: E402  (the nineteenth stop's script)
from tried_fill_from_raw import VARIANTS as FILL_VARIANTS  # noqa: E402  (the twenty-second stop's fill variants)
from tried_fill_from_raw import patch as fill_patch  # noqa: E402

try:  # the later layers' module until the twenty-seventh stop (its host_path: "whole" patches it)
    import torch_depth_sr.stream.crop_layers as crop_layers  # noqa: E402
except ImportError:
    import torch_depth_sr.stream.later_layers as crop_layers  # noqa: E402
import torch_depth_sr.stream.frame as frame  # noqa: E402
from torch_depth_sr import restore_depth  # noqa: E402
from torch_depth_sr.datasets.sequences import TUNING_SEQUENCES, make_sequence, recipe_sequences  # noqa: E402
from torch_depth_sr.evaluation.stream import regions, synthetic_metrics  # noqa: E402
from torch_depth_sr.stream import StreamRestorer, default_stream_model  # noqa: E402
from torch_depth_sr.window_max import dilate  # noqa: E402
from torch_depth_sr.stream.runs import JoinedRuns  # noqa: E402

SETS = {"tuning": lambda: list(TUNING_SEQUENCES),
        "fit": lambda: [*TUNING_SEQUENCES, *recipe_sequences(range(300, 304)), *recipe_sequences(range(400, 410))]}
SHIPPED = (crop_layers.host_path, frame.join_runs)


def near_join(radius, y, observed, static, candidate, noise, evidence, mean, departed, age, offset, scale, s):
    """``join_runs``' torch path, except that no departure is held out within ``radius`` px of a changed pixel."""
    near = dilate(~static, radius)
    o4, s4 = offset.view(-1, 1, 1, 1), scale.view(-1, 1, 1, 1)
    had = (mean > 0) & (evidence > 0)
    mean = (mean - o4) / s4
    limit = (s.outlier_test or math.inf) * noise
    pending = (departed - o4) / s4
    confirmed = (departed > 0) & (observed > 0) & ((y - pending).abs() <= limit)
    outlier = candidate & (evidence >= s.fill_evidence) & ~confirmed
    dropped = torch.where(outlier, y * s4 + o4, torch.zeros_like(y))
    observed = torch.where(outlier, torch.zeros_like(observed), observed)
    y = torch.where(outlier, torch.zeros_like(y), y)
    leaving = static & (observed > 0) & had & ((y - mean).abs() > limit)
    held_out = leaving & ~confirmed & (evidence >= s.fill_evidence) & ~near  # the one change
    departed = torch.where(held_out, y * s4 + o4, dropped)
    y = torch.where(held_out, mean, y)
    measured = observed > 0
    restarted = leaving & ~held_out
    averaged = static & measured & had & ~restarted
    y = torch.where(averaged, (y + evidence * mean) / (evidence + 1), y)
    unmeasured = ~measured & (evidence < s.fill_evidence)
    aged = torch.where(unmeasured, age.clamp(max=s.unmeasured_frames), age)
    weight = torch.where(static & ~restarted, s.weight * aged, torch.zeros_like(evidence))
    fresh = ~static | (age + 1 < s.settled_age())
    return JoinedRuns(y, observed, outlier, held_out, averaged, restarted, weight, departed, fresh)


def unpulled_join(radius, *args):
    """``join_runs`` as shipped, then no temporal prior within ``radius`` px of a changed pixel."""
    runs = SHIPPED[1](*args)
    near = dilate(~args[2], radius)
    return runs._replace(weight=torch.where(near, torch.zeros_like(runs.weight), runs.weight))


def use(variant: str) -> None:
    fill_patch("shipped")
    crop_layers.host_path, frame.join_runs = SHIPPED
    if variant.startswith("fill:") and variant[5:] in FILL_VARIANTS:
        fill_patch(variant[5:])
    elif variant == "whole":
        crop_layers.host_path = lambda device: False  # the device path: no crops
    elif variant.startswith("unpulled"):
        radius = int(variant[8:])
        frame.join_runs = lambda *a: unpulled_join(radius, *a)
    elif variant.startswith("near"):
        radius = int(variant[4:])
        frame.join_runs = lambda *a: near_join(radius, *a)
    elif variant != "shipped":
        raise SystemExit(f"unknown variant {variant!r}: shipped, whole, nearR, unpulledR (R in px) or fill:V, V one "
                         f"of {FILL_VARIANTS}")


def _scene(job) -> tuple[str, list]:
    spec, size, variants = job
    torch.set_num_threads(1)
    model = default_stream_model()
    seq = make_sequence(spec, frames=30, height=size[0], width=size[1])
    reg = regions(seq)
    base = synthetic_metrics(restored_frames(lambda d, c: restore_depth(d, c, model=model), seq), seq, reg)
    rows = []
    for v in variants:
        use(v)
        m = synthetic_metrics(restored_frames(StreamRestorer(model).step, seq), seq, reg)
        rows.append([m[k] / base[k] for k in KEYS])
    use("shipped")
    return spec.name, rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", default="480x640")
    p.add_argument("--set", choices=tuple(SETS), default="tuning")
    p.add_argument("--variants", nargs="+", default=["shipped", "whole"])
    p.add_argument("--processes", type=int, default=2)
    a = p.parse_args()
    size = tuple(int(t) for t in a.size.split("x"))
    for v in a.variants:
        use(v)  # an unknown name stops here, before any scene runs
    use("shipped")
    with Pool(a.processes) as pool:
        results = pool.map(_scene, [(s, size, a.variants) for s in SETS[a.set]()], chunksize=1)
    print(f"{a.set} at {a.size}, 30 frames")
    for name, rows in results:
        print(f"{name:22s} " + " | ".join(f"{v}: " + " ".join(f"{x:.4f}" for x in r) for v, r in zip(a.variants, rows)))
    print("(rmse flicker trail, stream ÷ frame by frame)")
    for i, v in enumerate(a.variants):
        r = np.array([rows[i] for _, rows in results])
        misses = [int((r[:, j] > LIMITS[k]).sum()) for j, k in enumerate(KEYS)]
        print(f"{v:8s} mean " + " ".join(f"{k} {x:.4f}" for k, x in zip(KEYS, r.mean(0)))
              + f" | scenes missing rmse/flicker/trail: {misses[0]}/{misses[1]}/{misses[2]} of {len(r)}")


if __name__ == "__main__":
    main()
