"""``torch-depth-sr bench --track stream``: temporal quality of depth *streams* (issue 28, item 2).

Methods (``--methods``; default all but ``rs-temporal+frame``):

* ``raw`` — the sensor's frames as they are;
* ``rs-temporal`` — the RealSense SDK's temporal filter
  (:class:`~torch_depth_sr.baselines.realsense.RealSenseTemporal`, ``pyrealsense2``, the optional extra ``bench-stream``) with the settings :data:`RS_TUNED` tuned on the synthetic
  *tuning* sequences (:func:`tune_realsense`), never on the evaluated ones;
* ``rs-temporal+frame`` — that filter, then the model on each frame;
* ``frame`` — the model (``--model``, a preset or a shipped name; default ``fast``) on each frame alone
  (:func:`~torch_depth_sr.restore_depth`);
* ``stream`` — the same model in a :class:`~torch_depth_sr.StreamRestorer`.

**Synthetic sequences** (``--sets synthetic``): :data:`~torch_depth_sr.datasets.sequences.STREAM_SEQUENCES`
(``--frames`` frames of ``--size``), with ground truth; with ``--seeds`` their recipes with those seeds instead
(:func:`~torch_depth_sr.datasets.sequences.recipe_sequences`: other scenes, to see how the figures carry over).
Outputs that keep holes (``raw``, ``rs-temporal``) have them pulled-pushed (:func:`~torch_depth_sr.fill.fill_holes`)
before they are scored, every pixel is scored; mm.

* ``rmse``, ``mae``: per frame, averaged over the frames;
* ``flicker``: the temporal std of the error over the frames from which the camera holds still, at the pixels whose
  ground truth and colour never change there (the mean over those pixels; ``flicker_med`` the median);
  ``flicker_step``: the mean absolute frame-to-frame change of the error there (a lasting change counts once);
* ``trail``: the RMSE over the pixels near moving objects — within 2 px of a mover now or covered by one in the 4
  frames before (what a temporal filter smears); NaN on a sequence without movers (no such pixel), and left out of
  the means over sequences (:func:`summarise`, :func:`tune_realsense`), which average the sequences that have one.

**Real sequences** (``--sets real``): ``real_sequences/realsense_static_tabletop`` and ``realsense_d435_t265_desk``
(the first ``--real-frames`` frames, every ``--real-stride``-th pixel), no ground truth; the models run with
``fill="trusted"`` (a hole they cannot fill confidently stays 0, as the raw stream and the RealSense filter leave
holes). On the static region (the top 150 rows of the tabletop; the desk camera moves, so its rows report no std):

* ``std_med``, ``std_p90``: the temporal std at the pixels measured in every raw frame (mm);
* ``toggling``: the share of the static region's pixels that switch between a value and a hole at least once;
  ``more_than_raw``: the share that switch more often than in the raw stream;
* ``fill_std``: the median temporal std, over the frames where the output has a value, at the pixels that are holes
  in some raw frames and measured in others (hole-fill stability); ``fill_std_never``: the same at the pixels never
  measured (only a method that fills them has a value there);
* ``holes``: the share of missing pixels in the output (whole frames).

``--figures DIR`` writes PNG pictures of a few frames and the flicker maps; ``--json`` the numbers.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Optional

import numpy as np
import torch

from ..errors import UsageError
from ..window_max import dilate

if TYPE_CHECKING:
    from ..model import DepthRestorer

__all__ = ["METHODS", "RS_TUNED", "REAL_SEQUENCES", "make_method", "run_stream_track", "synthetic_metrics",
           "real_metrics", "tune_realsense"]

METHODS = ("raw", "rs-temporal", "rs-temporal+frame", "frame", "stream")
DEFAULT_METHODS = ("raw", "rs-temporal", "frame", "stream")
REAL_SEQUENCES = {"realsense_static_tabletop": 150, "realsense_d435_t265_desk": 0}  # rows of the static region
# tuned by `python -m torch_depth_sr.evaluation.stream --tune-realsense` on the tuning sequences (30 frames, 120x160)
RS_TUNED = dict(alpha=0.05, delta=100.0, persistence=8)


# ---- methods -----------------------------------------------------------------------------------------------------
def _model(name: str, device: str):
    from ..model import named_model

    return named_model(name).to(device)


class _Method:
    """A restorer of one stream: ``step(depth uint16 (H,W), rgb (3,H,W) float) -> (H,W)``, ``reset()``."""

    def __init__(self, step: Callable, reset: Callable = lambda: None, model: Optional[torch.nn.Module] = None):
        self.step, self.reset, self.model = step, reset, model


def make_method(name: str, model: Optional["DepthRestorer"] = None, fill: str = "all",
                rs_params: Optional[dict] = None, device: str = "cpu") -> _Method:
    """The stream restorer ``name`` of :data:`METHODS` (``model``: the DepthRestorer of the model methods, default
    ``DepthRestorer()``; it is moved to ``device``, where the colour goes: the model computes on its own device)."""
    from ..model import DepthRestorer, restore_depth

    if name in ("rs-temporal+frame", "frame", "stream"):
        model = (DepthRestorer() if model is None else model).to(device)
    if name == "raw":
        return _Method(lambda d, rgb: d)
    if name in ("rs-temporal", "rs-temporal+frame"):
        from ..baselines.realsense import RealSenseTemporal

        rs = RealSenseTemporal(**(rs_params or RS_TUNED))
        if name == "rs-temporal":
            return _Method(lambda d, rgb: rs.step(d), rs.reset)

        def rs_frame(d, rgb):
            f = rs.step(d)
            if not (f > 0).any():
                return f
            with torch.no_grad():
                return restore_depth(f, rgb[None].to(device), model=model, fill=fill)
        return _Method(rs_frame, rs.reset, model)
    if name == "frame":
        def frame(d, rgb):
            with torch.no_grad():
                return restore_depth(d, rgb[None].to(device), model=model, fill=fill)
        return _Method(frame, model=model)
    if name == "stream":
        from ..stream import StreamRestorer

        stream = StreamRestorer(model, fill=fill)

        def step(d, rgb):
            with torch.no_grad():
                return stream.step(d, rgb[None].to(device))
        return _Method(step, stream.reset, model)
    raise UsageError(f"unknown stream method {name!r}; allowed are {list(METHODS)}")


def _run(method: _Method, depth: np.ndarray, rgb: np.ndarray) -> tuple[np.ndarray, float]:
    """Outputs (T,H,W) float32 of one stream and the mean seconds per frame."""
    method.reset()
    outs, t0 = [], time.perf_counter()
    for t in range(depth.shape[0]):
        outs.append(np.asarray(method.step(depth[t], torch.from_numpy(rgb[t])), dtype=np.float32))
    return np.stack(outs), (time.perf_counter() - t0) / depth.shape[0]


# ---- synthetic ---------------------------------------------------------------------------------------------------
def _filled(out: np.ndarray) -> np.ndarray:
    from ..fill import fill_holes

    if (out > 0).all():
        return out
    t = torch.from_numpy(out)[:, None]
    m = (t > 0).float()
    ok = m.flatten(1).any(1)
    res = t.clone()
    if ok.any():
        res[ok] = fill_holes(t[ok], m[ok])
    return res[:, 0].numpy()


def regions(seq: dict) -> dict:
    """The scored regions of a synthetic sequence: ``static`` (H,W) and its frames, ``trail`` (T,H,W)."""
    gt, rgb, moving = seq["gt"][:, 0], seq["rgb"], seq["moving"][:, 0]
    t0 = seq["hold_from"]
    static = (gt[t0:] == gt[t0]).all(0) & (rgb[t0:] == rgb[t0]).all(0).all(0)
    recent = np.stack([moving[max(0, t - 4):t].any(0) if t else np.zeros_like(moving[0]) for t in range(len(moving))])
    trail = dilate(torch.from_numpy(moving.astype(bool))[:, None], 2)[:, 0].numpy() | recent
    trail[0] = False
    return {"static": static, "frames": slice(t0, None), "trail": trail}


def synthetic_metrics(out: np.ndarray, seq: dict, reg: Optional[dict] = None) -> dict:
    """The scores of one method's outputs ``out`` (T,H,W) on a synthetic sequence (module docstring)."""
    reg = reg or regions(seq)
    gt = seq["gt"][:, 0]
    e = _filled(out).astype(np.float64) - gt
    rmse = np.sqrt((e ** 2).mean((1, 2)))
    es = e[reg["frames"]][:, reg["static"]]  # (T', N)
    std = es.std(0)
    return {"rmse": float(rmse.mean()), "mae": float(np.abs(e).mean()), "flicker": float(std.mean()),
            "flicker_med": float(np.median(std)), "flicker_step": float(np.abs(np.diff(es, axis=0)).mean()),
            "trail": _rms(e[reg["trail"]]), "static_share": float(reg["static"].mean())}


def _rms(e: np.ndarray) -> float:
    """The RMS of ``e``; NaN (documented, no warning) when it is empty: a region with no pixel has no score."""
    return float(np.sqrt((e ** 2).mean())) if e.size else float("nan")


def _nanmean(rows: list, axis: int = 0) -> np.ndarray:
    """The mean over sequences leaving out non-finite scores (NaN: a sequence with no pixel in a region), as
    :func:`summarise` does; NaN only where every sequence has none."""
    a = np.asarray(rows, dtype=np.float64)
    n = np.isfinite(a).sum(axis)
    return np.where(n > 0, np.where(np.isfinite(a), a, 0).sum(axis) / np.maximum(n, 1), np.nan)


def _synthetic(args, methods: dict, frames: int, size: tuple) -> tuple[list, dict]:
    from ..datasets.sequences import STREAM_SEQUENCES, make_sequence, recipe_sequences

    seeds = getattr(args, "seeds", None)
    rows, keep = [], {}
    for spec in recipe_sequences(seeds) if seeds else STREAM_SEQUENCES:
        seq = make_sequence(spec, frames=frames, height=size[0], width=size[1])
        reg = regions(seq)
        outs = {}
        for name, method in methods.items():
            out, secs = _run(method, seq["depth"][:, 0], seq["rgb"])
            outs[name] = out
            rows.append({"set": "synthetic", "sequence": spec.name, "method": name, "seconds": secs,
                         **synthetic_metrics(out, seq, reg)})
            print(f"  {spec.name:16s} {name:18s} rmse {rows[-1]['rmse']:.2f} flicker {rows[-1]['flicker']:.2f} "
                  f"trail {rows[-1]['trail']:.2f} ({secs:.2f} s/frame)", flush=True)
        keep[spec.name] = (seq, reg, outs)
    return rows, keep


# ---- real ----------------------------------------------------------------------------------------------------------
def _load_real(root: Path, name: str, frames: int, stride: int) -> tuple[np.ndarray, np.ndarray]:
    from ..datasets.io import read_depth, read_rgb
    from ..recordings import discover_recordings

    seqs = discover_recordings(root / "real_sequences" / name)
    if not seqs:
        raise UsageError(f"no recording under {root / 'real_sequences' / name}")
    depth, rgb = [], []
    for f in seqs[0].frames[:frames]:
        depth.append(read_depth(f.depth_path)[::stride, ::stride])
        rgb.append(read_rgb(f.rgb_path)[::stride, ::stride].transpose(2, 0, 1))
    return np.ascontiguousarray(np.stack(depth)).astype(np.uint16), np.ascontiguousarray(np.stack(rgb))


def _toggles(valid: np.ndarray) -> np.ndarray:
    return (valid[1:] != valid[:-1]).sum(0)


def real_metrics(out: np.ndarray, raw: np.ndarray, static_rows: int) -> dict:
    """The scores of one method's outputs ``out`` (T,H,W) on a real sequence whose raw frames are ``raw``
    (module docstring); ``static_rows``: the height of the static region (0: none)."""
    r = {"holes": float((out <= 0).mean())}
    if static_rows <= 0:
        valid, raw_valid = out > 0, raw > 0
        r.update(toggling=float((_toggles(valid) > 0).mean()),
                 more_than_raw=float((_toggles(valid) > _toggles(raw_valid)).mean()))
        return r
    o, y = out[:, :static_rows].astype(np.float64), raw[:, :static_rows].astype(np.float64)
    always = (y > 0).all(0)
    std = o[:, always].std(0) if (o[:, always] > 0).all() else np.where(o[:, always] > 0, o[:, always], np.nan)
    if not isinstance(std, np.ndarray) or std.ndim == 2:
        std = np.nanstd(std, 0)
    valid, raw_valid = o > 0, y > 0
    tog, tog_raw = _toggles(valid), _toggles(raw_valid)
    def fill_std(where: np.ndarray) -> float:
        ov = np.where(valid, o, np.nan)[:, where]
        enough = valid[:, where].sum(0) >= 2
        return float(np.nanmedian(np.nanstd(ov[:, enough], 0))) if enough.any() else float("nan")

    sometimes = (~raw_valid).any(0) & raw_valid.any(0)
    never = (~raw_valid).all(0)
    r.update(std_med=float(np.nanmedian(std)), std_p90=float(np.nanpercentile(std, 90)),
             toggling=float((tog > 0).mean()), more_than_raw=float((tog > tog_raw).mean()),
             fill_std=fill_std(sometimes), fill_std_never=fill_std(never), measured_share=float(always.mean()))
    return r


def _real(args, methods: dict, root: Path, frames: int, stride: int) -> tuple[list, dict]:
    rows, keep = [], {}
    for name, static_rows in REAL_SEQUENCES.items():
        depth, rgb = _load_real(root, name, frames, stride)
        outs = {}
        for m, method in methods.items():
            out, secs = _run(method, depth, rgb)
            outs[m] = out
            rows.append({"set": "real", "sequence": name, "method": m, "seconds": secs,
                         **real_metrics(out, depth, (static_rows + stride - 1) // stride)})
            print(f"  {name:26s} {m:18s} " + " ".join(f"{k} {v:.4g}" for k, v in rows[-1].items()
                                                       if isinstance(v, float)), flush=True)
        keep[name] = (depth, rgb, outs, (static_rows + stride - 1) // stride)
    return rows, keep


# ---- figures -------------------------------------------------------------------------------------------------------
def _figures(folder: Path, synthetic: dict, real: dict) -> list[Path]:
    from ..figures import depth_to_bgr, error_to_bgr, mosaic, rgb_to_bgr, write_png

    written = []
    heat = lambda a, vmax: __import__("cv2").applyColorMap(  # noqa: E731
        np.clip(np.nan_to_num(a) / vmax * 255, 0, 255).astype(np.uint8), 2)  # COLORMAP_JET
    for name, (seq, reg, outs) in list(synthetic.items())[:2]:
        gt = seq["gt"][:, 0]
        lo, hi = float(np.percentile(gt, 0.5)), float(np.percentile(gt, 99.5))
        T = gt.shape[0]
        rows, labels = [], []
        for t in sorted({T // 3, 2 * T // 3, T - 1}):
            rows.append([rgb_to_bgr(seq["rgb"][t])] + [depth_to_bgr(o[t], lo, hi) for o in outs.values()]
                        + [depth_to_bgr(gt[t], lo, hi)])
            labels.append([f"frame {t}"] + list(outs) + ["ground truth"])
            rows.append([np.full_like(rows[-1][0], 255)] + [error_to_bgr(_filled(o[t:t + 1])[0], gt[t],
                                                                         np.ones_like(gt[t]), 50.0)
                                                           for o in outs.values()] + [np.full_like(rows[-1][0], 255)])
            labels.append(["|error|, 0-50 mm"] + [f"|{m} - gt|" for m in outs] + [""])
        written.append(write_png(folder / f"stream_{name}_frames.png", mosaic(rows, labels)))
        st = reg["static"]
        maps = []
        for m, o in outs.items():
            s = (_filled(o)[reg["frames"]] - gt[reg["frames"]]).std(0)
            s[~st] = 0
            maps.append(heat(s, 20.0))
        written.append(write_png(folder / f"stream_{name}_flicker.png", mosaic([maps], [list(outs)])))
    for name, (depth, rgb, outs, rows_static) in real.items():
        valid = depth[depth > 0]
        lo, hi = float(np.percentile(valid, 1)), float(np.percentile(valid, 99))
        t = depth.shape[0] - 1
        top = [rgb_to_bgr(rgb[t])] + [depth_to_bgr(o[t].astype(np.float32), lo, hi) for o in outs.values()]
        labels = [[f"frame {t}"] + list(outs)]
        rows = [top]
        if rows_static > 0:
            maps = [np.full_like(top[0], 255)]
            for o in outs.values():
                a = np.where(o > 0, o, np.nan).astype(np.float64)
                s = np.nanstd(a, 0)
                s[rows_static:] = 0
                maps.append(heat(s, 5.0))
            rows.append(maps)
            labels.append(["temporal std, top rows (0-5 mm)"] + list(outs))
        written.append(write_png(folder / f"stream_{name}.png", mosaic(rows, labels)))
    return written


# ---- the track -----------------------------------------------------------------------------------------------------
def _size(text) -> tuple[int, int]:
    try:
        h, w = (int(v) for v in str(text).lower().split("x"))
        return h, w
    except ValueError:
        raise UsageError(f"--size must be HxW, e.g. 120x160; got {text!r}") from None


def summarise(rows: list[dict]) -> list[dict]:
    """Mean per (set, method) over the sequences (the real set per sequence)."""
    out = []
    for s in ("synthetic", "real"):
        keys = dict.fromkeys((r["sequence"] if s == "real" else "", r["method"]) for r in rows if r["set"] == s)
        for seqname, m in keys:
            sel = [r for r in rows if r["set"] == s and r["method"] == m and (s != "real" or r["sequence"] == seqname)]
            agg = {"set": s, "sequence": seqname or f"mean of {len(sel)}", "method": m}
            for k in sel[0]:
                vals = [r[k] for r in sel if isinstance(r.get(k), float) and np.isfinite(r[k])]
                if vals:
                    agg[k] = float(np.mean(vals))
            out.append(agg)
    return out


def run_stream_track(args: argparse.Namespace) -> int:
    from .._data_root import data_root
    from .report import metadata, print_table

    methods = list(getattr(args, "methods", None) or DEFAULT_METHODS)
    for m in methods:
        if m not in METHODS:
            raise UsageError(f"unknown stream method {m!r}; allowed are {list(METHODS)}")
    sets = list(getattr(args, "sets", None) or ("synthetic", "real"))
    if set(sets) - {"synthetic", "real"}:
        raise UsageError(f"--sets for track stream: synthetic and/or real; got {sets}")
    device = getattr(args, "device", "cpu") or "cpu"
    from ..stream import DEFAULT_STREAM_MODEL

    model_name = getattr(args, "model", None) or DEFAULT_STREAM_MODEL
    model = _model(model_name, device) if {"frame", "stream", "rs-temporal+frame"} & set(methods) else None
    if any(m.startswith("rs-") for m in methods):
        from ..baselines.realsense import realsense_available, INSTALL_HINT

        if not realsense_available():
            print(f"torch-depth-sr: skipping {[m for m in methods if m.startswith('rs-')]}: {INSTALL_HINT}")
            methods = [m for m in methods if not m.startswith("rs-")]
    frames = int(getattr(args, "frames", None) or 30)
    size = _size(getattr(args, "size", None) or "120x160")
    rows, syn, real = [], {}, {}
    if "synthetic" in sets:
        print(f"synthetic sequences: {frames} frames of {size[0]}x{size[1]}, model {model_name!r}", flush=True)
        fill = "all"
        r, syn = _synthetic(args, {m: make_method(m, model, fill, device=device) for m in methods}, frames, size)
        rows += r
    if "real" in sets:
        root = Path(args.data) if getattr(args, "data", None) else data_root()
        rf, stride = int(getattr(args, "real_frames", None) or 30), int(getattr(args, "real_stride", None) or 2)
        print(f"real sequences: {rf} frames, every {stride}th pixel, model {model_name!r} (fill='trusted')", flush=True)
        r, real = _real(args, {m: make_method(m, model, "trusted", device=device) for m in methods}, root, rf, stride)
        rows += r
    summary = summarise(rows)
    syn_cols = ["method", "rmse", "mae", "flicker", "flicker_med", "flicker_step", "trail", "seconds"]
    real_cols = ["sequence", "method", "std_med", "std_p90", "toggling", "more_than_raw", "fill_std",
                 "fill_std_never", "holes", "seconds"]
    if syn:
        print_table([r for r in summary if r["set"] == "synthetic"], syn_cols,
                    f"track stream, synthetic: mean over {len(syn)} sequences ({frames} frames, {size[0]}x{size[1]}), "
                    f"model {model_name!r}, mm")
        if getattr(args, "per_scene", False):
            print_table([r for r in rows if r["set"] == "synthetic"], ["sequence"] + syn_cols, "per sequence")
    if real:
        print_table([r for r in summary if r["set"] == "real"], real_cols, f"track stream, real: model {model_name!r}")
    if getattr(args, "figures", None):
        for p in _figures(Path(args.figures), syn, real):
            print(f"figure: {p}")
    if getattr(args, "json", None):
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        meta = metadata(device)
        meta.update(track="stream", model=model_name, frames=frames, size=list(size), sets=sets,
                    seeds=getattr(args, "seeds", None), rs_params=RS_TUNED)
        Path(args.json).write_text(json.dumps({"metadata": meta, "summary": summary, "results": rows}, indent=1))
        print(f"json: {args.json}")
    return 0


# ---- tuning the RealSense filter -----------------------------------------------------------------------------------
RS_GRID = dict(alpha=(0.05, 0.1, 0.2, 0.4, 0.6, 0.8), delta=(5.0, 10.0, 20.0, 40.0, 80.0, 100.0),
               persistence=tuple(range(9)))


def tune_realsense(frames: int = 30, size: tuple = (120, 160), grid: Optional[dict] = None) -> list[dict]:
    """Score every setting of ``grid`` (default :data:`RS_GRID`) on the tuning sequences
    (:data:`~torch_depth_sr.datasets.sequences.TUNING_SEQUENCES`): ``score`` = RMSE / raw RMSE + flicker / raw
    flicker, averaged over the sequences (lower is better); sorted best first."""
    import itertools

    from ..baselines.realsense import RealSenseTemporal
    from ..datasets.sequences import TUNING_SEQUENCES, make_sequence

    grid = grid or RS_GRID
    seqs = [make_sequence(s, frames=frames, height=size[0], width=size[1]) for s in TUNING_SEQUENCES]
    regs = [regions(s) for s in seqs]
    raw = [synthetic_metrics(s["depth"][:, 0].astype(np.float32), s, r) for s, r in zip(seqs, regs)]
    out = []
    for a, d, p in itertools.product(grid["alpha"], grid["delta"], grid["persistence"]):
        scores = []
        for s, r, ref in zip(seqs, regs, raw):
            f = RealSenseTemporal(a, d, p)
            o = np.stack([f.step(s["depth"][t, 0]) for t in range(frames)]).astype(np.float32)
            m = synthetic_metrics(o, s, r)
            scores.append((m["rmse"] / ref["rmse"] + m["flicker"] / ref["flicker"], m["rmse"], m["flicker"],
                           m["trail"]))
        sc = _nanmean(scores, 0)  # a tuning sequence without movers has no trail: left out of the trail mean
        out.append(dict(alpha=a, delta=d, persistence=p, score=float(sc[0]), rmse=float(sc[1]),
                        flicker=float(sc[2]), trail=float(sc[3])))
    return sorted(out, key=lambda r: r["score"])


if __name__ == "__main__":  # python -m torch_depth_sr.evaluation.stream --tune-realsense
    p = argparse.ArgumentParser(description="tune the RealSense temporal filter on the synthetic tuning sequences")
    p.add_argument("--tune-realsense", action="store_true", required=True)
    p.add_argument("--frames", type=int, default=30)
    p.add_argument("--size", default="120x160")
    a = p.parse_args()
    res = tune_realsense(a.frames, _size(a.size))
    from .report import print_table

    print_table(res[:15], ["alpha", "delta", "persistence", "score", "rmse", "flicker", "trail"],
                f"RealSense temporal filter on the tuning sequences ({a.frames} frames, {a.size}), best 15 of "
                f"{len(res)}; score = rmse/raw + flicker/raw")
    print_table(sorted(res, key=lambda r: r["rmse"])[:3], ["alpha", "delta", "persistence", "score", "rmse", "flicker",
                                                          "trail"], "lowest rmse")
    print_table(sorted(res, key=lambda r: r["flicker"])[:3], ["alpha", "delta", "persistence", "score", "rmse",
                                                             "flicker", "trail"], "lowest flicker")
