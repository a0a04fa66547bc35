"""Speed against accuracy: the front of the speed tiers and the baselines, and a few model settings.

``python -m torch_depth_sr.evaluation.tradeoffs --front OUT [--bench-json PAPER.json SENSOR.json ...]`` (issue 27)
writes the speed–accuracy picture: for the paper's model, every speed tier (``fast``, ``default``, ``best``),
the frozen ``full`` model (the default tier until 2026-12-04) and every baseline (``jbf``, ``rgf``, ``dictionary``,
kornia's 9×9 JBF ``kornia-jbf9``), x = seconds per 640×480 frame (each method alone in a fresh process, 2 threads
unless ``--threads``, median of ``--repeats`` after a warm-up, on a synthetic frame degraded by the track's protocol;
kornia's JBF timed in the same process gives the ratio) and y = RMSE on the ten held-out 2005/2003/2001 scenes
(the protocol of ``torch-depth-sr bench --track paper|sensor``; taken from ``bench --json`` files when given, else
run here), one panel per track:
``OUT/front.png``, ``OUT/front.md`` (the table) and ``OUT/front.json``.

``python -m torch_depth_sr.evaluation.tradeoffs [--configs JSON ...] [--part accuracy|timing|both]``

* accuracy: mean RMSE of tracks ``paper`` and ``sensor`` over the full images of the eleven Middlebury
  2006 scenes (the split the defaults were fitted on; the other scenes are for reporting);
* timing: median seconds of the model on a 640×480 synthetic frame (σ = 5, 5 % holes), after a warm-up,
  with the threads torch has.

Each config is a JSON dict of :class:`~torch_depth_sr.RestorerConfig` overrides as
:func:`~torch_depth_sr.config.apply_overrides` takes them (version-2 groups, dotted paths, or version-1 flat
names); ``{}`` is the default.
"""
from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path
from typing import Callable, Optional, Sequence, Union

import numpy as np
import torch

from ..config import RestorerConfig, apply_overrides
from ..model import DepthRestorer
from .tune import errors_by, fitting_samples

__all__ = ["DEFAULT_CONFIGS", "FRONT_METHODS", "HELD_OUT", "accuracy", "front", "timing", "main"]

# the methods of the speed-accuracy picture (bench method names) and the held-out scenes it reports on
FRONT_METHODS = ("paper-model", "fast", "default", "full", "best", "jbf", "rgf", "dictionary", "kornia-jbf9")
HELD_OUT = ("Art", "Books", "Dolls", "Laundry", "Moebius", "Reindeer", "Cones", "Teddy", "Tsukuba", "Venus")
_LABEL = {"paper-model": "paper", "fast": "fast", "default": "default", "full": "full (frozen)", "best": "best",
          "jbf": "jbf", "rgf": "rgf", "dictionary": "dictionary", "kornia-jbf9": "kornia JBF 9x9"}

DEFAULT_CONFIGS = (
    {},
    {"block_matching": {"search_window": 11, "match_layers": [2]}},  # the "fast" preset's window and re-matching
    {"block_matching": {"search_window": 11, "match_layers": [2], "k": 6}},
    {"block_matching": {"search_window": 11, "match_layers": [2]}, "num_layers": 5},
    {"block_matching": {"search_window": 7, "match_layers": [2]}},
    {"block_matching": {"match_layers": []}},
    {"block_matching": {"block_size": 5}},
)


def _model(overrides: dict) -> DepthRestorer:
    return DepthRestorer(apply_overrides(RestorerConfig(), overrides))


def accuracy(overrides: dict, samples: Sequence[dict]) -> dict:
    """Mean RMSE over GT-known pixels, per track."""
    return {t: float(np.mean(v)) for t, v in errors_by(_model(overrides), samples, "track").items()}


def timing(overrides: dict, height: int = 480, width: int = 640, repeats: int = 3) -> float:
    """Median seconds of one restoration of a synthetic frame, after a warm-up."""
    from .speed import make_inputs

    y, rgb, _ = make_inputs(height, width, 1)
    model = _model(overrides)
    times = []
    with torch.no_grad():
        model(y, rgb)
        for _ in range(repeats):
            t0 = time.perf_counter()
            model(y, rgb)
            times.append(time.perf_counter() - t0)
    return statistics.median(times)


def _timing_input(track: str, height: int = 480, width: int = 640) -> dict:
    """A synthetic 640×480 frame degraded by the track's protocol (a timing input, not a benchmark scene)."""
    from ..datasets.synthetic import make_scene
    from ..degradations import make_degradation

    s = make_degradation(track)(make_scene(height, width, seed=0))
    return {"depth": s["depth"].clamp_min(0), "rgb": s["rgb"]}


def time_method(method: str, track: str, repeats: int = 3, threads: Optional[int] = None) -> dict:
    """Seconds of ``run_method(method, ...)`` on a 640×480 frame of ``track``'s kind in this process: median (and
    minimum) of ``repeats`` after a warm-up, and kornia's 9×9 JBF on the same frame."""
    from .methods import run_method

    if threads:
        torch.set_num_threads(int(threads))
    sample = _timing_input(track)
    out = {}
    for m in (method, "kornia-jbf9"):
        run_method(m, sample, track=track)
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            run_method(m, sample, track=track)
            times.append(time.perf_counter() - t0)
        out[m] = times
    return {"method": method, "track": track, "seconds": statistics.median(out[method]), "min": min(out[method]),
            "kornia": statistics.median(out["kornia-jbf9"]), "threads": torch.get_num_threads(),
            "load": list(__import__("os").getloadavg())}


def _time_isolated(method: str, track: str, repeats: int, threads: Optional[int]) -> dict:
    import subprocess
    import sys

    code = ("import json,sys; from torch_depth_sr.evaluation.tradeoffs import time_method; "
            "print('@@' + json.dumps(time_method(*json.loads(sys.argv[1]))))")
    p = subprocess.run([sys.executable, "-c", code, json.dumps([method, track, repeats, threads])],
                       capture_output=True, text=True)
    for line in p.stdout.splitlines():
        if line.startswith("@@"):
            return json.loads(line[2:])
    raise RuntimeError(f"timing {method} on {track} failed: {(p.stderr or p.stdout)[-2000:]}")


def _held_out_errors(method: str, track: str, bench: Optional[dict]) -> dict:
    """Mean RMSE / MAE of ``method`` over the held-out scenes: from a ``bench --json`` file's per-scene rows, or
    by the bench protocol here."""
    rows = []
    if bench is not None:
        rows = [r for r in bench["results"] if r["method"] == method and r["scene"] in HELD_OUT]
    if not rows:
        from .._data_root import data_root
        from .bench import _metrics, _samples
        from .methods import run_method

        for rec, sample in _samples(track, data_root(), list(HELD_OUT), None):
            rows.append({"scene": rec.name, **_metrics(run_method(method, sample, track=track).cpu(), sample, track)})
    if {r["scene"] for r in rows} != set(HELD_OUT):
        raise RuntimeError(f"{method} on {track}: held-out scenes {sorted(r['scene'] for r in rows)}")
    return {k: float(np.mean([r[k] for r in rows])) for k in ("rmse", "mae")}


def _plot(rows: list[dict], path) -> None:
    """Two panels (paper, sensor): RMSE against seconds (log scale), one labelled point per method, the methods
    no other beats in both time and error joined (the front). OpenCV drawing (no plotting library needed)."""
    import math

    import cv2

    from ..figures import write_png

    pw, ph, m = 560, 420, 70
    img = np.full((ph + 40, 2 * pw, 3), 255, np.uint8)
    for panel, track in enumerate(("paper", "sensor")):
        pts = [r for r in rows if r["track"] == track]
        x0 = panel * pw
        xs = [math.log10(r["seconds"]) for r in pts]
        ys = [r["rmse"] for r in pts]
        xlo, xhi = math.floor(min(xs) * 2) / 2, math.ceil(max(xs) * 2) / 2 + 0.25
        ylo, yhi = 0.0, max(ys) * 1.1

        def px(lx, y):
            return (int(x0 + m + (lx - xlo) / (xhi - xlo) * (pw - m - 20)),
                    int(40 + (1 - (y - ylo) / (yhi - ylo)) * (ph - m)))

        cv2.rectangle(img, px(xlo, yhi), px(xhi, ylo), (0, 0, 0), 1)
        e = math.ceil(xlo)
        while e <= xhi:
            for mult in (1, 2, 5):
                lx = e + math.log10(mult)
                if xlo <= lx <= xhi:
                    a, b = px(lx, ylo), px(lx, yhi)
                    cv2.line(img, a, b, (225, 225, 225), 1)
                    cv2.putText(img, f"{10 ** lx:g}", (a[0] - 12, a[1] + 16), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1)
            e += 1
        step = 0.5 if yhi < 4 else 1.0
        yv = 0.0
        while yv <= yhi:
            a = px(xlo, yv)
            cv2.putText(img, f"{yv:.1f}", (a[0] - 32, a[1] + 4), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1)
            yv += step
        front = sorted((r for r in pts if not any(o["seconds"] <= r["seconds"] and o["rmse"] < r["rmse"]
                                                   and o is not r for o in pts)), key=lambda r: r["seconds"])
        for a, b in zip(front, front[1:]):
            cv2.line(img, px(math.log10(a["seconds"]), a["rmse"]), px(math.log10(b["seconds"]), b["rmse"]),
                     (60, 160, 60), 2)
        for r in pts:
            ours = r["method"] in ("paper-model", "fast", "default", "full", "best")
            c = (200, 60, 20) if ours else (40, 40, 200)
            p = px(math.log10(r["seconds"]), r["rmse"])
            cv2.circle(img, p, 5, c, -1)
            cv2.putText(img, _LABEL[r["method"]], (p[0] + 7, p[1] - 5), cv2.FONT_HERSHEY_SIMPLEX, 0.45, c, 1)
        cv2.putText(img, f"{track}: held-out RMSE vs seconds per 640x480 frame", (x0 + m - 40, 25),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1)
        cv2.putText(img, "seconds (log scale); blue: this library, red: baselines, green: the front",
                    (x0 + m - 40, ph + 30), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (0, 0, 0), 1)
    write_png(path, img)


def _merged_bench(files: Sequence[Union[str, Path]]) -> dict:
    """``bench --json`` files by track: the rows of every file, where a later file's method replaces that method's
    rows of the files before it (a method added, or measured again after a change: never the mean of two runs)."""
    bench: dict = {}
    for f in files:
        data = json.loads(Path(f).read_text())
        rows = bench.setdefault(data["metadata"]["track"], {"results": []})["results"]
        again = {r["method"] for r in data["results"]}
        rows[:] = [r for r in rows if r["method"] not in again] + list(data["results"])
    return bench


def front(out: Union[str, Path], bench_json: Sequence[str] = (), methods: Sequence[str] = FRONT_METHODS,
          repeats: int = 3, threads: Optional[int] = 2, log: Callable[[str], None] = print) -> list[dict]:
    """The speed-accuracy picture (module docstring): ``out/front.png``, ``front.md``, ``front.json``."""

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    bench = _merged_bench(bench_json)
    rows = []
    for track in ("paper", "sensor"):
        for m in methods:
            err = _held_out_errors(m, track, bench.get(track))
            t = _time_isolated(m, track, repeats, threads)
            rows.append({"track": track, "method": m, **err, "seconds": t["seconds"], "min_seconds": t["min"],
                         "x_kornia": t["seconds"] / t["kornia"], "kornia_seconds": t["kornia"],
                         "threads": t["threads"], "load": t["load"][0]})
            log(f"{track:6s} {m:12s} RMSE {err['rmse']:.3f} MAE {err['mae']:.3f}  {t['seconds']:.3f} s "
                f"({rows[-1]['x_kornia']:.1f}x kornia, load {t['load'][0]:.1f})")
    lines = ["| track | method | held-out RMSE | held-out MAE | s per 640×480 frame | × kornia JBF 9×9 |",
             "|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['track']} | {_LABEL[r['method']]} | {r['rmse']:.3f} | {r['mae']:.3f} | "
                     f"{r['seconds']:.3f} | {r['x_kornia']:.1f} |")
    (out / "front.md").write_text("\n".join(lines) + "\n")
    (out / "front.json").write_text(json.dumps({"rows": rows, "held_out": HELD_OUT, "repeats": repeats,
                                                "threads": threads}, indent=1))
    _plot(rows, out / "front.png")
    log(f"wrote {out / 'front.png'}, {out / 'front.md'}, {out / 'front.json'}")
    return rows


def main(argv: Optional[Sequence[str]] = None) -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--front", default=None, metavar="OUT",
                   help="write the speed-accuracy picture of the tiers and baselines to this folder")
    p.add_argument("--bench-json", nargs="*", default=[],
                   help="with --front: bench --json files of tracks paper and sensor to take the errors from (a "
                        "later file's rows of a method replace the earlier files')")
    p.add_argument("--methods", nargs="*", default=list(FRONT_METHODS), help="with --front: the methods")
    p.add_argument("--threads", type=int, default=2, help="with --front: torch threads of the timing")
    p.add_argument("--configs", nargs="*", default=None,
                   help='JSON dicts of RestorerConfig overrides (docs/config.md), e.g. '
                        '\'{"block_matching": {"k": 10}}\', '
                        '\'{"block_matching.k": 10}\' or the version-1 \'{"k": 10}\'')
    p.add_argument("--part", choices=["accuracy", "timing", "both"], default="both")
    p.add_argument("--repeats", type=int, default=3)
    args = p.parse_args(argv)
    if args.front:
        front(args.front, args.bench_json, args.methods, args.repeats, args.threads)
        return 0
    configs = [json.loads(c) for c in args.configs] if args.configs else [dict(c) for c in DEFAULT_CONFIGS]
    for c in configs:  # refuse a mistyped name before the first run
        apply_overrides(RestorerConfig(), c)
    samples = fitting_samples(None, n_synthetic=0) if args.part != "timing" else None
    print(f"threads={torch.get_num_threads()}; RMSE: 2006 scenes, full images; seconds: 640x480 synthetic")
    for c in configs:
        cells = []
        if samples is not None:
            cells += [f"{t} {v:.4f}" for t, v in accuracy(c, samples).items()]
        if args.part != "accuracy":
            cells.append(f"{timing(c, repeats=args.repeats):.3f} s")
        print(f"{json.dumps(c, sort_keys=True):65s} " + "  ".join(cells), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
