"""``torch-depth-sr restore``: files or folders of depth (+ colour) in, same names, units and dtype out.

Every argument is checked before anything is read or written (:func:`plan_restore`, :class:`UsageError`):
the output format comes from ``-o``'s suffix, an existing output is kept unless ``--overwrite`` (or skipped with
``--skip-existing``), an input is replaced only with ``--in-place`` and a colour image never. A map is written
with its input's dtype or not at all, atomically. In a folder, a file that fails is reported at the end and the
others are still written.
"""
from __future__ import annotations

import argparse
import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset
from tqdm import tqdm

from .datasets.io import depth_suffixes_for, read_depth_stored, read_rgb, write_depth, \
    write_png_depth
from .datasets.files import DEPTH_EXTS, RGB_EXTS
from .datasets.files import as_numpy as _as_numpy
from .datasets.files import check_writable as _check_writable
from .datasets.files import describe_files as _files
from .datasets.files import file_identity as _identity
from .datasets.files import pair_folders as _pair_folders
from .datasets.files import stored_layout as _stored_layout
from .datasets.files import to_model_input as _to_model_input
from .datasets.files import with_path as _with_path
from .errors import DepthSRError, ModelFileError, UsageError

__all__ = ["DEPTH_EXTS", "RGB_EXTS", "FORMATS_HELP", "Job", "DepthFilePairs", "plan_restore", "restore_paths"]

FORMATS_HELP = (".png (uint8 or uint16), .pfm (float32), .npy (any dtype), .tif/.tiff (what OpenCV stores: "
                "integers, float32, float64) or .pgm (uint16, little-endian)")


@dataclass(frozen=True)
class Job:
    """One depth file to restore and where its results go."""

    depth: Path
    rgb: Optional[Path]
    target: Path
    confidence: Optional[Path] = None
    skip: bool = False  # --skip-existing and the target exists


class DepthFilePairs(Dataset):
    """Jobs read in DataLoader workers: ``{"index", "depth" (stored dtype), "rgb", "error"}``.

    A file that cannot be read comes back with its exception in ``"error"`` so that the others go on.
    """

    def __init__(self, jobs: list[Job]):
        self.jobs = jobs

    def __len__(self) -> int:
        return len(self.jobs)

    def __getitem__(self, i: int) -> dict:
        job = self.jobs[i]
        try:
            d = read_depth_stored(job.depth)
            rgb = None if job.rgb is None else read_rgb(job.rgb)
        except Exception as e:  # noqa: BLE001 - reported with the file's name by the caller
            return {"index": i, "depth": None, "rgb": None, "error": e}
        return {"index": i, "depth": d, "rgb": rgb, "error": None}


def _keep(item: dict) -> dict:
    """DataLoader ``collate_fn``: arrays as read (the default turns them into tensors, losing uint16 and byte order)."""
    return item


# ---- planning: every check that needs no file content ---------------------------------------------------------

def plan_restore(args: argparse.Namespace) -> list[Job]:
    """The jobs of a ``restore`` command line, or :class:`UsageError` before anything is read or written."""
    depth_in = Path(args.depth)
    rgb_in = Path(args.rgb) if args.rgb else None
    if args.output is None and not args.in_place:
        raise UsageError("the following argument is required: -o/--output (or --in-place to replace the input)")
    if args.in_place and args.skip_existing:
        raise UsageError("--in-place and --skip-existing contradict each other (every output exists: it is the "
                         "input); use one of them")
    _check_input(depth_in, "depth")
    if rgb_in is not None:
        _check_input(rgb_in, "colour")
    if args.scale_factor not in (None, 1) and rgb_in is None:
        raise UsageError(f"--scale-factor {args.scale_factor} needs the high-resolution colour image: "
                         "torch-depth-sr restore DEPTH RGB -o OUT --scale-factor N")
    jobs = _plan_folder(depth_in, rgb_in, args) if depth_in.is_dir() else [_plan_file(depth_in, rgb_in, args)]
    return _check_targets(jobs, args)


def _check_input(p: Path, what: str) -> None:
    if not p.exists():
        raise UsageError(f"{what} input '{p}' does not exist; check the path")
    if p.is_file() and what == "depth" and p.suffix.lower() not in DEPTH_EXTS:
        raise UsageError(f"depth input '{p}' has the suffix '{p.suffix}'; allowed are {', '.join(DEPTH_EXTS)} "
                         "(lossy formats such as JPEG cannot hold depth)")


def _is_folder_arg(arg: str) -> bool:
    """An existing folder, or a name ending in a path separator (a folder to create)."""
    return Path(arg).is_dir() or arg.endswith(("/", os.sep))


def _plan_file(depth: Path, rgb: Optional[Path], args) -> Job:
    if rgb is not None and rgb.is_dir():
        raise UsageError(f"depth '{depth}' is a file, so the colour must be a file too; got the folder '{rgb}'")
    if args.output is None:
        target = depth
    elif _is_folder_arg(args.output):
        target = Path(args.output) / depth.name
    else:
        target = Path(args.output)
        if target.suffix.lower() not in DEPTH_EXTS:
            what = f"the suffix '{target.suffix}'" if target.suffix else "no suffix"
            raise UsageError(f"-o '{target}' has {what}; name the output {FORMATS_HELP}, or give an existing "
                             "folder (or a name ending in /) to write the input's name inside it")
    return Job(depth, rgb, target, _confidence_path(args.confidence, depth, folder=False))


def _confidence_path(arg: Optional[str], depth: Path, folder: bool) -> Optional[Path]:
    if arg is None:
        return None
    if folder or _is_folder_arg(arg):
        if Path(arg).is_file():
            raise UsageError(f"--confidence '{arg}' is a file; a folder of depth maps needs a folder of confidences")
        return Path(arg) / f"{depth.stem}_confidence.png"
    if Path(arg).suffix.lower() != ".png":
        raise UsageError(f"--confidence '{arg}' must end in .png (an 8-bit map, 255 = fully trusted) or be a folder")
    return Path(arg)


def _plan_folder(depth_dir: Path, rgb_dir: Optional[Path], args) -> list[Job]:
    if rgb_dir is not None and not rgb_dir.is_dir():
        raise UsageError(f"depth '{depth_dir}' is a folder, so the colour must be a folder too; got the file "
                         f"'{rgb_dir}'")
    out = depth_dir if args.output is None else Path(args.output)
    if out.exists() and not out.is_dir():
        raise UsageError(f"-o '{out}' is a file; a folder of depth maps needs an output folder")
    if not out.exists() and out.suffix.lower() in DEPTH_EXTS and not args.output.endswith(("/", os.sep)):
        raise UsageError(f"-o '{out}' looks like a file name, but the depth input is a folder; give an output folder")
    depths, rgbs = _pair_folders(depth_dir, rgb_dir)
    return [Job(d, c, out / d.name, _confidence_path(args.confidence, d, folder=True)) for d, c in zip(depths, rgbs)]


def _check_targets(jobs: list[Job], args) -> list[Job]:
    """Refuse outputs that would replace an input or an existing file; mark those that --skip-existing skips."""
    depth_ids = {_identity(j.depth): j.depth for j in jobs}
    colour_ids = {_identity(j.rgb) for j in jobs if j.rgb is not None}
    existing, checked_folders, seen = [], set(), set()
    for job in jobs:
        for out in [job.target] + ([job.confidence] if job.confidence else []):
            name = os.path.normcase(os.path.abspath(out))
            if name in seen:
                raise UsageError(f"'{out}' would be written twice (as a depth map and a confidence map); give "
                                 "--confidence another name")
            seen.add(name)
            out_id = _identity(out)
            if out_id is not None and out_id in colour_ids:
                raise UsageError(f"the output '{out}' is a colour input; choose another output (colour is never "
                                 "replaced, not even with --in-place)")
            replaced = depth_ids.get(out_id) if out_id is not None else None
            if replaced is not None and not (args.in_place and out is job.target and replaced == job.depth):
                raise UsageError(f"the output '{out}' would replace the input '{replaced}'; add --in-place to "
                                 "replace the input with its restored map, or choose another output")
            if out.is_dir():
                raise UsageError(f"the output '{out}' is a folder; choose a file name")
            if out_id is not None and replaced is None and not args.overwrite:
                existing.append((job, out))
            if out.parent not in checked_folders:
                _check_writable(out)
                checked_folders.add(out.parent)
    # a confidence map left by an interrupted run is made again with its depth map
    skipped = {id(j) for j, out in existing if args.skip_existing and out is j.target}
    refused = [out for _, out in existing if not args.skip_existing]
    if refused:
        raise UsageError(f"{_files(refused)} already exist{'s' if len(refused) == 1 else ''}; add --overwrite to "
                         "replace, or --skip-existing to keep what exists and restore the rest (nothing was written)")
    return [Job(j.depth, j.rgb, j.target, j.confidence, skip=id(j) in skipped) for j in jobs]


# ---- running -----------------------------------------------------------------------------------------------------

def restore_paths(args: argparse.Namespace) -> int:
    """Run ``restore``: 0 when every output was written or skipped.

    Raises:
        UsageError: before anything is read or written, or (one file) when ``-o`` cannot hold the input's dtype.
        DepthSRError: one file failed, or some files of a folder failed (each is reported on stderr first).
    """
    jobs = plan_restore(args)
    model = _load_model(args)
    if not Path(args.depth).is_dir():
        return _restore_single(model, jobs[0], args)
    return _restore_folder(model, jobs, args)


def _load_model(args):
    """The model ``--preset`` or ``--pretrained`` names, on ``--device``; None when neither: each file then gets
    what ``restore_depth`` runs without a model (:func:`~torch_depth_sr.model.default_model`)."""
    from .model import load_named_model

    return load_named_model(getattr(args, "preset", None), args.pretrained, args.device)


def _restore_single(model, job: Job, args) -> int:
    if job.skip:
        print(f"skipped {job.target} (exists; --skip-existing)")
        return 0
    try:
        depth = read_depth_stored(job.depth)
        rgb = None if job.rgb is None else read_rgb(job.rgb)
        written = _restore_one(model, job, depth, rgb, args)
    except UsageError:
        raise
    except DepthSRError as e:
        raise DepthSRError(_with_path(e, job.depth)) from e
    for p in written:
        print(f"wrote {p}")
    return 0


def _restore_folder(model, jobs: list[Job], args) -> int:
    from .errors import describe_error

    todo = [j for j in jobs if not j.skip]
    loader = DataLoader(DepthFilePairs(todo), batch_size=None, num_workers=args.workers, collate_fn=_keep)
    failures, done = [], 0
    # disable=None: a bar on terminals, nothing in logs
    bar = tqdm(loader, total=len(todo), desc="restore", unit="file", disable=None)
    for item in bar:
        job = todo[item["index"]]
        try:
            if item["error"] is not None:
                raise item["error"]
            _restore_one(model, job, item["depth"], item["rgb"], args)
            done += 1
        except Exception as e:  # noqa: BLE001 - one bad file must not lose the others; --debug stops here
            if getattr(args, "debug", False):
                raise
            failures.append((job, e))
            bar.set_postfix(failed=len(failures))
    bar.close()
    out = jobs[0].target.parent
    skipped = len(jobs) - len(todo)
    print(f"wrote {done} of {len(jobs)} files to {out}" + (f" (skipped {skipped} existing)" if skipped else ""))
    if not failures:
        return 0
    for job, e in failures:
        print(f"torch-depth-sr: {_with_path(e, job.depth, describe_error(e))}", file=sys.stderr)
    names = ", ".join(j.depth.name for j, _ in failures[:3]) + (", ..." if len(failures) > 3 else "")
    raise DepthSRError(f"{len(failures)} of {len(todo)} files failed ({names}; see above); the others were written "
                       "- fix or remove those files and rerun with --skip-existing")


def _restore_one(model, job: Job, depth: np.ndarray, rgb: Optional[np.ndarray], args) -> list[Path]:
    """Restore one map and write it (confidence first, so an existing depth output means a finished file)."""
    suffix = job.target.suffix.lower()
    if suffix not in depth_suffixes_for(depth.dtype):
        raise UsageError(f"-o '{job.target}': {suffix} cannot hold the input's {depth.dtype.name} depth without "
                         f"changing it; write it as {_formats_for(depth.dtype)} (the output "
                         "keeps the input's dtype and units; nothing was written)")
    from .model import restore_depth

    rgb_t = None if rgb is None else torch.from_numpy(np.ascontiguousarray(rgb)).permute(2, 0, 1)[None].to(args.device)
    if model is None:  # restore_depth's default for this file (denoising or guided upsampling), on --device
        from .model import default_model_for

        model = default_model_for(depth, rgb, args.scale_factor, args.device)
    with torch.no_grad():
        res = restore_depth(_to_model_input(depth), rgb_t, model=model, scale_factor=args.scale_factor,
                            return_details=True)
    restored = _as_numpy(res.depth).astype(depth.dtype, copy=False)
    written = []
    if job.confidence is not None:
        conf = _as_numpy(res.confidence).astype(np.float64)
        job.confidence.parent.mkdir(parents=True, exist_ok=True)
        write_png_depth(job.confidence, conf.reshape(conf.shape[-2:]) * 255, bits=8)
        written.append(job.confidence)
    job.target.parent.mkdir(parents=True, exist_ok=True)
    write_depth(job.target, _stored_layout(restored, job.depth))
    return [job.target] + written


def _formats_for(dtype) -> str:
    names = " or ".join(depth_suffixes_for(dtype))
    return names.replace(".tif or .tiff", ".tif/.tiff")