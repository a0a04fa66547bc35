"""What a benchmark run writes besides its numbers: run metadata and plain-text tables.

Shared by ``bench``, ``speed``, ``gpu_report`` and the command line's demo (it lived in ``cli.py``, which made
the evaluation scripts import the command line).
"""
from __future__ import annotations

from pathlib import Path

import torch

from ..precision import native_bfloat16, precision_override

__all__ = ["metadata", "print_table"]


def metadata(device: str = "cpu") -> dict:
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
            # the networks' arithmetic (torch_depth_sr.precision): what overrides every model's setting (None: their
            # own, "auto" for the shipped ones), and what "auto" runs on this device
            "network_precision": precision_override(),
            "auto_networks": "bfloat16" if native_bfloat16(torch.device(device)) else "float32",
            **_gpu_metadata(device)}


def _gpu_metadata(device: str) -> dict:
    if not str(device).startswith("cuda") or not torch.cuda.is_available():
        return {}
    props = torch.cuda.get_device_properties(torch.device(device))
    return {"gpu": props.name, "gpu_memory_gb": round(props.total_memory / 2**30, 1), "cuda": torch.version.cuda}


def print_table(rows: list[dict], cols: list[str], title: str = "") -> None:
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
