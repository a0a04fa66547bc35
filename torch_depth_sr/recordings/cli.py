"""``torch-depth-sr restore --recordings ROOT OUT``: the command-line side of :func:`restore_dataset`.

``torch_depth_sr/cli.py`` adds these arguments to ``restore`` (:func:`add_recordings_arguments`) and hands a
command line with ``--recordings`` to :func:`restore_recordings`.
"""
from __future__ import annotations

import argparse
import os
import sys

from ..errors import DepthSRError, UsageError
from .layouts import TUM_MAX_DIFFERENCE

__all__ = ["RECORDINGS_HELP", "add_recordings_arguments", "restore_recordings"]

RECORDINGS_HELP = """\
torch-depth-sr restore --recordings ROOT OUT restores every frame of every recording under ROOT into OUT (the one
positional argument), each sequence in order, several sequences at once with --workers N, and across processes
and machines under torchrun (each sequence whole on one rank). A recording is a folder with associations.txt or
depth.txt + rgb.txt (TUM RGB-D), index.txt ('id depth/<file> rgb/<file>' per line) or depth/ + rgb/ folders.
Outputs: OUT/<sequence>/<depth path in the recording>, with the input's format, dtype and units; OUT/manifest.jsonl
records every frame (input, output, seconds, status). An interrupted run continues with --resume (finished frames
are kept); existing outputs are replaced only with --overwrite. See docs/recordings.md."""


def _seconds(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of seconds > 0, got {text!r}") from None
    if not v > 0:
        raise argparse.ArgumentTypeError(f"expected a number of seconds > 0, got {v}")
    return v


def _threads(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {v}")
    return v


def add_recordings_arguments(parser: argparse.ArgumentParser) -> None:
    """The ``--recordings`` options of ``restore`` (``--overwrite``, ``--workers``, ``--preset``, ``--pretrained``, ``--device``
    and ``--scale-factor`` are ``restore``'s own and keep their meaning)."""
    g = parser.add_argument_group("whole recordings (--recordings ROOT OUT)", RECORDINGS_HELP)
    g.add_argument("--recordings", metavar="ROOT", default=None,
                   help="restore the recordings under this folder into the folder given as the positional argument")
    g.add_argument("--resume", action="store_true",
                   help="continue the run recorded in OUT/manifest.jsonl (finished frames are kept); on a new OUT it "
                        "simply starts, so a command with --resume can be rerun as it is after an interruption")
    g.add_argument("--threads", type=_threads, default=None,
                   help="torch threads per process (default: as set by OMP_NUM_THREADS/torch; --workers share them); "
                        "runs that must give identical bits need the same value")
    g.add_argument("--stream", action="store_true",
                   help="restore each sequence as a stream (torch_depth_sr.StreamRestorer: a frame helped by the "
                        "frames before it - less flicker, holes held from a confident past, cheaper frames), with the "
                        "stream's model denoise-fast unless --preset or --pretrained names another; default: every "
                        "frame on its own, as restore does. See docs/stream.md")
    g.add_argument("--max-time-difference", type=_seconds, default=None, metavar="SECONDS",
                   help="TUM depth.txt + rgb.txt: largest time between a depth frame and its colour frame "
                        f"(default {TUM_MAX_DIFFERENCE})")


_NOT_WITH_RECORDINGS = (
    ("rgb", "a colour argument (a recording's colour is found with its depth)"),
    ("output", "-o (the output folder is the positional argument: restore --recordings ROOT OUT)"),
    ("in_place", "--in-place (recordings are never replaced)"),
    ("skip_existing", "--skip-existing (use --resume: finished frames are kept)"),
    ("confidence", "--confidence (not written for recordings)"),
)


def restore_recordings(args: argparse.Namespace) -> int:
    """Run ``restore --recordings``; 0 when every frame is restored. Rank 0 prints the summary."""
    from .restore import restore_dataset
    from .restorers import PretrainedRestorer

    for name, what in _NOT_WITH_RECORDINGS:
        if getattr(args, name, None):
            raise UsageError(f"--recordings does not take {what}")
    if getattr(args, "resume", False) and getattr(args, "skip_existing", False):
        raise UsageError("--resume and --skip-existing: use --resume alone")
    kwargs = {} if args.scale_factor is None else {"scale_factor": args.scale_factor}
    factory = PretrainedRestorer(args.pretrained, args.device, stream=bool(getattr(args, "stream", False)),
                                 preset=getattr(args, "preset", None), **kwargs)
    factory.load_model()  # an unknown --preset or --pretrained name: one line, before anything is read or written
    rank = int(os.environ.get("RANK", "0") or 0)
    try:
        summary = restore_dataset(args.recordings, args.depth, restorer=factory, workers=args.workers,
                                  resume=args.resume, overwrite=args.overwrite, threads=args.threads,
                                  max_time_difference=_max_time_difference(args))
    except UsageError:
        if rank != 0:  # rank 0's plan, raised on every rank: rank 0 prints it
            return 2
        raise
    if rank != 0:
        return 0 if summary.ok else 1  # rank 0 reports for all
    s = summary
    by = f" ({s.processes} processes)" if s.processes > 1 else ""
    line = (f"restored {s.sequences} sequence{'s' if s.sequences != 1 else ''} ({s.frames} frames) into {s.out} in "
            f"{s.seconds:.1f} s{by}: {s.written} written, {s.skipped} already done, {s.failed} failed; "
            f"manifest {s.manifest}")
    if s.unmatched:
        line += (f"; {s.unmatched} TUM depth frames had no colour frame within {_max_time_difference(args)} s "
                 "(left out)")
    print(line)
    if s.ok:
        return 0
    for r in s.failures[:20]:
        print(f"torch-depth-sr: {r['sequence']} frame {r['index']}: {r['error']}", file=sys.stderr)
    if len(s.failures) > 20:
        print(f"torch-depth-sr: ... and {len(s.failures) - 20} more failed frames (see the manifest)", file=sys.stderr)
    raise DepthSRError(f"{s.missing} of {s.frames} frames are not restored (see above and {s.manifest}); the others "
                       "were written - fix the inputs and rerun with --resume")


def _max_time_difference(args) -> float:
    """``--max-time-difference``, or its default when not given (None marks "not given": restore without
    --recordings refuses the flag)."""
    given = getattr(args, "max_time_difference", None)
    return TUM_MAX_DIFFERENCE if given is None else given
