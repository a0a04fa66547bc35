"""Command line: ``torch-depth-sr {demo,restore,bench,train,train-refiner,warmup}``."""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from contextlib import contextmanager
from typing import Iterator, Optional, Sequence
from pathlib import Path

import torch

from .evaluation.report import metadata as _metadata, print_table as _print_table
from .precision import ENVIRONMENT_VARIABLE, NETWORK_PRECISIONS


def cmd_demo(args: argparse.Namespace) -> int:
    from .datasets.synthetic import make_scene
    from .degradations import SensorDegradation
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
    for name, preset in (("tv", "tv"), ("full", "full")):
        model = DepthRestorer.from_preset(preset)
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
    if not ok:  # the demo is the smoke test of the install: a model that stopped working must fail it
        print(f"torch-depth-sr demo: error: expected RMSE(full) < RMSE(tv) < RMSE(input); got full "
              f"{rows[2]['rmse']:.4f}, tv {rows[1]['rmse']:.4f}, input {rows[0]['rmse']:.4f}", file=sys.stderr)
        return 1
    return 0


RESTORE_HELP = """\
Restore depth maps: a file, or a folder of them (with an optional colour file or folder, paired by name).

Output format: from -o's suffix: .png (uint8 or uint16), .pfm (float32), .npy (any dtype), .tif/.tiff (integers,
float32, float64) or .pgm (uint16, little-endian). The output always has the input's dtype and units; a format
that cannot hold them (float into PNG, integers into PFM) is refused with the formats that can, nothing converted.
An unknown suffix (.txt, or lossy .jpg) is refused before anything is read. -o FOLDER (an existing folder or a
name ending in /) writes FOLDER/<input name>; a folder of inputs keeps each file's name and format.

Safety: an existing output is kept unless --overwrite (or skipped with --skip-existing, which resumes an
interrupted folder); an input is replaced only with --in-place, a colour image never. Files are written whole
(a temporary .<name>.*.part file next to the output, then renamed). In a folder, a file that fails is reported
at the end and the others are written (exit status 1).

Exit status: 0 done, 1 a file could not be restored or written, 2 a usage mistake (nothing was written).
"""


def cmd_restore(args: argparse.Namespace) -> int:
    # ---- issue 28: whole recordings (torch_depth_sr/recordings/cli.py) ----
    if getattr(args, "recordings", None) is not None:
        from .recordings.cli import restore_recordings

        return restore_recordings(args)
    recordings_only = (("stream", "--stream"), ("resume", "--resume"), ("max_time_difference", "--max-time-difference"))
    for name, flag in recordings_only:
        if getattr(args, name, None) not in (None, False):  # recordings-only flags, else silently ignored
            from .errors import UsageError

            raise UsageError(f"{flag} applies only with --recordings ROOT OUT")
    # ---- end issue 28 ----
    from .restore_files import restore_paths

    return restore_paths(args)


def cmd_bench(args: argparse.Namespace) -> int:
    from .evaluation.bench import run_bench

    return run_bench(args)


def cmd_warmup(args: argparse.Namespace) -> int:
    """Compile the numba CPU kernels into numba's on-disk cache before the first forward (``make install`` runs it)."""
    from . import native, warmup
    from .errors import DepthSRError

    if native.numba_disabled():
        print("torch-depth-sr warmup: TORCH_DEPTH_SR_NO_NUMBA is set: the numba kernels are off, nothing to compile")
        return 0
    names = list(dict.fromkeys(args.dtype))
    try:
        native.cpu_kernel("singular_kernel", "singular_rounds_cpu", required=True)
    except DepthSRError:  # numba missing or broken: one line, exit status 1 (make install stops there)
        raise DepthSRError(f"{native._FAILED}: there are no kernels to compile (the forward would run the slower "
                           "torch path)") from None
    print(f"torch-depth-sr warmup: compiling the numba CPU kernels for {', '.join(names)} into numba's cache "
          f"{native.kernel_cache_dir()} (about {native.COMPILE_SECONDS * len(names)} s when it is empty; later runs "
          "only load them)", flush=True)
    report = warmup.warmup([getattr(torch, n) for n in names], log=lambda line: print(f"  {line}", flush=True))
    print(f"torch-depth-sr warmup: done in {report['seconds']:.1f} s: {report['compiled']} kernel signature(s) "
          f"compiled, {report['loaded']} loaded from the cache")
    return 0


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (no usage block), like every other mistake of the command line."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _whole_number(minimum: int):
    """An argparse type: a whole number ``>= minimum``, with a one-line message otherwise."""

    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number >= {minimum}, got {text!r}") from None
        if v < minimum:
            raise argparse.ArgumentTypeError(f"expected a whole number >= {minimum}, got {v}")
        return v

    return parse


_positive_int = _whole_number(1)
_non_negative_int = _whole_number(0)


def _add_debug(p: argparse.ArgumentParser, default=False) -> None:
    p.add_argument("--debug", action="store_true", default=default,
                   help="show the Python traceback of an error instead of its one-line message")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="torch-depth-sr", description="Colour-guided depth-map restoration.")
    _add_debug(p)
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    d = sub.add_parser("demo", help="restore a synthetic scene (no files needed) and print a table")
    d.add_argument("--out", default="out/demo", help="folder for the PNG figure")
    d.add_argument("--json", default=None, help="write results as JSON")
    d.add_argument("--height", type=int, default=240)
    d.add_argument("--width", type=int, default=320)
    d.add_argument("--seed", type=int, default=0)
    d.set_defaults(func=cmd_demo)

    r = sub.add_parser("restore", help="restore depth files (PNG 8/16-bit, PFM, NPY, TIFF) or folders of them",
                       description=RESTORE_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    r.add_argument("depth", help="depth file or folder")
    r.add_argument("rgb", nargs="?", default=None, help="colour file or folder (same names/order)")
    r.add_argument("-o", "--output", default=None,
                   help="output file (format from its suffix) or folder; required unless --in-place")
    exists = r.add_mutually_exclusive_group()
    exists.add_argument("--overwrite", action="store_true", help="replace existing output files (never inputs)")
    exists.add_argument("--skip-existing", action="store_true",
                        help="keep existing outputs and restore only the others (resume an interrupted folder)")
    r.add_argument("--in-place", action="store_true",
                   help="allow the result to replace its depth input (without -o: always); never a colour image")
    r.add_argument("--device", default="cpu")
    r.add_argument("--scale-factor", type=_positive_int, default=None,
                   help="guided upsampling factor (default: from the sizes of depth and colour)")
    r.add_argument("--confidence", default=None,
                   help="also write the confidence map (8-bit PNG, 255 = trusted) to this .png file or folder")
    named = r.add_mutually_exclusive_group()
    named.add_argument("--preset", default=None,
                       help="a named model (DepthRestorer.from_preset): the speed tiers fast, default, best, or full, "
                            "paper, ... (docs/speed.md). Default: what restore_depth runs, the default tier to denoise "
                            "and the frozen full model for guided upsampling")
    named.add_argument("--pretrained", default=None,
                       help="name of shipped parameters (see DepthRestorer.from_pretrained)")
    r.add_argument("--workers", type=_non_negative_int, default=0, help="DataLoader workers for folders")
    _add_network_precision(r)
    r.set_defaults(func=cmd_restore)
    # ---- issue 28: restore --recordings ROOT OUT (torch_depth_sr/recordings/cli.py) ----
    from .recordings.cli import add_recordings_arguments

    add_recordings_arguments(r)
    # ---- end issue 28 ----

    b = sub.add_parser("bench", help="benchmarks on the shared Middlebury data (see README)")
    b.add_argument("--track", required=True,
                   choices=["paper", "sensor", "upsample-a", "upsample-b", "real", "speed", "gdsr", "stream"])
    b.add_argument("--data", default=None, help="data root (default: $TORCH_DEPTH_SR_DATA or ../shared/data)")
    b.add_argument("--methods", nargs="*", default=None)
    b.add_argument("--scenes", nargs="*", default=None,
                   help="scene names (track gdsr: file keys, e.g. 02 30 for Middlebury, 1000 for NYU, RGB-D-D timestamps)")
    b.add_argument("--sigma", type=float, default=None, help="noise std for track paper (grey levels)")
    b.add_argument("--sets", nargs="+", default=None,
                   help="track gdsr: Middlebury Lu NYUDepthv2_Test RGBDD RGBDD_Test_Realscene (default: Middlebury "
                        "Lu); track stream: synthetic real (default both)")
    b.add_argument("--scales", nargs="+", type=_whole_number(2), default=None, help="track gdsr: default 4 8 16")
    b.add_argument("--noise", nargs="+", type=float, default=None,
                   help="track gdsr: noise std on a 0-255 scale of each image's range (default 0)")
    b.add_argument("--max-images", type=_positive_int, default=None,
                   help="track gdsr: at most this many images per set, evenly spaced (a quick subset of RGBDD)")
    b.add_argument("--model", default=None,
                   help="track stream: the model of the methods frame and stream, a preset or a shipped name "
                        "(default denoise-fast, the stream's model)")
    b.add_argument("--frames", type=_positive_int, default=None, help="track stream: frames per synthetic sequence "
                   "(default 30)")
    b.add_argument("--size", default=None, help="track stream: HxW of the synthetic sequences (default 120x160)")
    b.add_argument("--seeds", type=_non_negative_int, nargs="+", default=None,
                   help="track stream: the synthetic recipes with these seeds instead of the evaluated sequences "
                        "(1-3; the tuning ones are 101-103): the figures on other scenes")
    b.add_argument("--real-frames", type=_positive_int, default=None,
                   help="track stream: first frames of each real sequence (default 30)")
    b.add_argument("--real-stride", type=_positive_int, default=None,
                   help="track stream: every n-th pixel of the real frames (default 2)")
    b.add_argument("--json", default=None)
    b.add_argument("--figures", default=None)
    b.add_argument("--save-inputs", default=None)
    b.add_argument("--per-scene", action="store_true", help="print per-scene rows")
    b.add_argument("--device", default="cpu")
    b.add_argument("--config", default=None,
                   help='JSON of RestorerConfig overrides for the model methods tv, tv+nl, full, full-fast, '
                        'paper-model (docs/config.md), e.g. \'{"block_matching": {"block_size": 5}}\', '
                        '\'{"block_matching.block_size": 5}\' or the version-1 \'{"block_size": 5}\'')
    b.add_argument("--pretrained", default=None, metavar="FOLDER",
                   help="methods trained, trained-refined, trained-x4, trained-upsample(-area) (gdsr: trained) load "
                        "this saved model folder (e.g. runs/x/best) instead of the shipped parameters")
    _add_network_precision(b)
    b.set_defaults(func=cmd_bench)

    wu = sub.add_parser("warmup", help="compile the numba CPU kernels now (once per install; make install runs it)",
                        description="Compile every numba CPU kernel the forward can call (block matching, re-matching, "
                                    "nonlocal terms, singular test) into numba's on-disk cache, so that the first "
                                    "forward does not wait for it. A second run only loads them.")
    wu.add_argument("--dtype", nargs="+", choices=["float32", "float64"], default=["float32", "float64"],
                    help="the input dtypes to compile for (default: both)")
    wu.set_defaults(func=cmd_warmup)

    from .training.cli import add_train_parser, add_train_refiner_parser

    add_train_parser(sub)
    add_train_refiner_parser(sub)
    for name, sp in sub.choices.items():
        _add_debug(sp, default=argparse.SUPPRESS)  # also after the command; SUPPRESS keeps the top-level value
    return p


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run the command line; returns the exit status (0 done, 1 failure, 2 usage mistake), never raises
    except with ``--debug``, which lets the exception and its traceback through."""
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as e:  # --help (0), or an argument error already printed on one line (2)
        return e.code if isinstance(e.code, int) else 2
    try:
        _check_device(getattr(args, "device", None))
        with _network_precision_of(args):
            return args.func(args)
    except KeyboardInterrupt:
        if args.debug:
            raise
        print("torch-depth-sr: interrupted (outputs already written are complete)", file=sys.stderr)
        return 130
    except SystemExit as e:  # a library part that still exits by itself with a message
        if args.debug or not isinstance(e.code, str):
            raise
        print(f"torch-depth-sr: error: {_single_line(e.code)}", file=sys.stderr)
        return 2
    except Exception as e:  # noqa: BLE001 - every mistake is one line; --debug shows the traceback
        if args.debug:
            raise
        from .errors import UsageError

        print(f"torch-depth-sr: error: {describe_error(e)}", file=sys.stderr)
        return 2 if isinstance(e, UsageError) else 1


from .errors import describe_error, single_line as _single_line  # noqa: E402  (one home: errors.py)

__all__ = ["cmd_demo", "RESTORE_HELP", "cmd_restore", "cmd_bench", "cmd_warmup", "build_parser", "main"]


def _add_network_precision(p: argparse.ArgumentParser) -> None:
    p.add_argument("--network-precision", choices=NETWORK_PRECISIONS, default=None,
                   help="the arithmetic of the models' networks (torch_depth_sr.precision): auto (bfloat16 on a CPU "
                        "with AMX or AVX512-BF16, else float32; the default), float32 (the same numbers on every "
                        "machine) or bfloat16; passed to every worker process and torchrun rank")


@contextmanager
def _network_precision_of(args: argparse.Namespace) -> Iterator[None]:
    """``--network-precision`` as the environment variable the library reads, for this command and the processes it
    starts (spawned workers do not inherit a ``network_precision`` block); the environment as it was afterwards."""
    value = getattr(args, "network_precision", None)
    if value is None:
        yield
        return
    before = os.environ.get(ENVIRONMENT_VARIABLE)
    os.environ[ENVIRONMENT_VARIABLE] = value
    try:
        yield
    finally:
        if before is None:
            os.environ.pop(ENVIRONMENT_VARIABLE, None)
        else:
            os.environ[ENVIRONMENT_VARIABLE] = before


def _check_device(name) -> None:
    """Refuse a device torch does not know or cannot use here, before any work."""
    if name is None:
        return
    from .errors import UsageError

    try:
        dev = torch.device(name)
    except (RuntimeError, TypeError) as e:
        raise UsageError(f"--device {name!r} is not a device ({_single_line(e)}); use cpu, cuda or cuda:N") from e
    if dev.type == "cuda":
        if not torch.cuda.is_available():
            why = "this torch is built without CUDA" if torch.version.cuda is None else "no CUDA GPU is visible"
            raise UsageError(f"--device {name}: CUDA is not available ({why}); use --device cpu")
        if dev.index is not None and dev.index >= torch.cuda.device_count():
            raise UsageError(f"--device {name}: there are only {torch.cuda.device_count()} CUDA device(s); "
                             f"use cuda:0 to cuda:{torch.cuda.device_count() - 1}")
    elif dev.type == "mps" and not torch.backends.mps.is_available():
        raise UsageError(f"--device {name}: MPS is not available here; use --device cpu")
    elif dev.type == "meta":
        raise UsageError(f"--device {name}: the meta device holds no data; use cpu or cuda")
    elif dev.type not in ("cpu", "cuda", "mps"):  # xpu and the like: ask torch's module of that name
        backend = getattr(torch, dev.type, None)
        if backend is not None and hasattr(backend, "is_available") and not backend.is_available():
            raise UsageError(f"--device {name}: {dev.type} is not available here; use --device cpu")


if __name__ == "__main__":
    sys.exit(main())
