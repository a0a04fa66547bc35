"""Command line: ``torch-depth-sr {demo,restore,bench,train}``."""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import torch


def _metadata(device: str = "cpu") -> dict:
    import datetime
    import platform
    import subprocess

    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5,
                                cwd=Path(__file__).parent).stdout.strip() or None
    except Exception:  # git missing or not a checkout
        commit = None
    import kornia

    return {"date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"), "commit": commit,
            "torch": torch.__version__, "kornia": kornia.__version__, "python": platform.python_version(),
            "device": device, "threads": torch.get_num_threads(), "cpu": platform.processor() or platform.machine(),
            **_gpu_metadata(device)}


def _gpu_metadata(device: str) -> dict:
    if not str(device).startswith("cuda") or not torch.cuda.is_available():
        return {}
    props = torch.cuda.get_device_properties(torch.device(device))
    return {"gpu": props.name, "gpu_memory_gb": round(props.total_memory / 2**30, 1), "cuda": torch.version.cuda}


def _print_table(rows: list[dict], cols: list[str], title: str = "") -> None:
    if title:
        print(title)
    widths = {c: max(len(c), *(len(_fmt(r.get(c))) for r in rows)) for c in cols}
    print("  ".join(c.ljust(widths[c]) for c in cols))
    print("  ".join("-" * widths[c] for c in cols))
    for r in rows:
        print("  ".join(_fmt(r.get(c)).ljust(widths[c]) for c in cols))


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.4f}" if abs(v) < 1000 else f"{v:.1f}"
    return "" if v is None else str(v)


def cmd_demo(args) -> int:
    from .datasets.synthetic import make_scene
    from .evaluation.protocols import SensorDegradation
    from .figures import comparison_figure
    from .fill import fill_holes
    from .metrics import mae, rmse
    from .model import DepthRestorer

    torch.manual_seed(0)
    scene = make_scene(args.height, args.width, seed=args.seed)
    scene = {**scene, "name": f"synthetic-{args.seed}"}
    sample = SensorDegradation(seed=args.seed)(scene)
    y = sample["depth"][None]
    rgb = sample["rgb"][None]
    gt, valid = scene["gt"][None], scene["mask"][None]
    rows, preds = [], {}
    t0 = time.perf_counter()
    preds["input"] = fill_holes(y, (y > 0).float())
    secs = {"input": time.perf_counter() - t0}
    for name in ("tv", "full"):
        model = DepthRestorer.ablation(name)
        t0 = time.perf_counter()
        preds[name] = model(y, rgb)
        secs[name] = time.perf_counter() - t0
    for name, p in preds.items():
        rows.append({"scene": scene["name"], "method": name, "rmse": float(rmse(p, gt, valid)),
                     "mae": float(mae(p, gt, valid)), "seconds": secs[name]})
    _print_table(rows, ["method", "rmse", "mae", "seconds"],
                 f"synthetic scene {args.height}x{args.width}, sensor degradation (noise, holes, flying pixels)")
    out = Path(args.out)
    fig = comparison_figure(out / "demo.png", rgb, y, gt, valid, {k: v for k, v in preds.items() if k != "input"})
    print(f"figure: {fig}")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps({"metadata": _metadata(), "results": rows}, indent=2))
        print(f"json: {args.json}")
    ok = rows[2]["rmse"] < rows[1]["rmse"] < rows[0]["rmse"]
    if not ok:
        print("warning: expected RMSE(full) < RMSE(tv) < RMSE(input)", file=sys.stderr)
    return 0


def cmd_restore(args) -> int:
    from .restore_files import restore_paths

    return restore_paths(args)


def cmd_bench(args) -> int:
    from .evaluation.bench import run_bench

    return run_bench(args)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="torch-depth-sr", description="Colour-guided depth-map restoration.")
    sub = p.add_subparsers(dest="command", required=True)

    d = sub.add_parser("demo", help="restore a synthetic scene (no files needed) and print a table")
    d.add_argument("--out", default="out/demo", help="folder for the PNG figure")
    d.add_argument("--json", default=None, help="write results as JSON")
    d.add_argument("--height", type=int, default=240)
    d.add_argument("--width", type=int, default=320)
    d.add_argument("--seed", type=int, default=0)
    d.set_defaults(func=cmd_demo)

    r = sub.add_parser("restore", help="restore depth files (PNG 8/16-bit, PFM, NPY) or folders of them")
    r.add_argument("depth", help="depth file or folder")
    r.add_argument("rgb", nargs="?", default=None, help="colour file or folder (same names/order)")
    r.add_argument("-o", "--output", required=True, help="output file or folder")
    r.add_argument("--device", default="cpu")
    r.add_argument("--scale-factor", type=int, default=None, help="guided upsampling factor (default: from sizes)")
    r.add_argument("--confidence", default=None, help="also write the confidence map (PNG 8-bit) here")
    r.add_argument("--pretrained", default=None, help="name of shipped parameters (see DepthRestorer.from_pretrained)")
    r.add_argument("--workers", type=int, default=0, help="DataLoader workers for folders")
    r.set_defaults(func=cmd_restore)

    b = sub.add_parser("bench", help="benchmarks on the shared Middlebury data (see README)")
    b.add_argument("--track", required=True, choices=["paper", "sensor", "upsample-a", "upsample-b", "real", "speed"])
    b.add_argument("--data", default=None, help="data root (default: $TORCH_DEPTH_SR_DATA or ../shared/data)")
    b.add_argument("--methods", nargs="*", default=None)
    b.add_argument("--scenes", nargs="*", default=None)
    b.add_argument("--sigma", type=float, default=None, help="noise std for track paper (grey levels)")
    b.add_argument("--json", default=None)
    b.add_argument("--figures", default=None)
    b.add_argument("--save-inputs", default=None)
    b.add_argument("--per-scene", action="store_true", help="print per-scene rows")
    b.add_argument("--device", default="cpu")
    b.add_argument("--config", default=None,
                   help='JSON of RestorerConfig overrides for tv, tv+nl, full (e.g. \'{"block_size": 5}\')')
    b.set_defaults(func=cmd_bench)

    from .training.cli import add_train_parser

    add_train_parser(sub)
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
