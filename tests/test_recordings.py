"""Whole recordings (issue 28 items 3-4): discovery of each layout, the manifest, every frame written once, no
overwrite without asking, resume after a kill (bit-identical), process pools and a two-process torchrun run."""
from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from torch_depth_sr.cli import main
from torch_depth_sr.errors import UsageError
from torch_depth_sr.recordings import (FrameByFrame, PretrainedRestorer, Sequence, associate_timestamps,
                                       discover_recordings, read_manifest, restore_dataset)
from torch_depth_sr.recordings.manifest import ManifestWriter, merge_manifest, shard_path

H, W = 32, 40
TESTS = Path(__file__).resolve().parent
REPO = TESTS.parent
COUNTS = (5, 4, 3)  # frames of the three synthetic sequences (torchrun: rank 0 gets 5, rank 1 gets 4 + 3)


# ---- synthetic recordings ------------------------------------------------------------------------------------

def _depth(seq: int, k: int) -> np.ndarray:
    """uint16 millimetres with holes; pixel (0, 0) names the frame (seq, k) for the logs."""
    rng = np.random.default_rng(100 * seq + k)
    d = 800 + 40 * seq + 10 * k + np.linspace(0, 600, W)[None] + rng.normal(0, 8, (H, W))
    d = d.astype(np.uint16)
    d[rng.random((H, W)) < 0.08] = 0
    d[0, 0] = 1000 * (seq + 1) + k
    return d


def _colour(seq: int, k: int) -> np.ndarray:
    rng = np.random.default_rng(7 + 100 * seq + k)
    return (rng.random((H, W, 3)) * 255).astype(np.uint8)


def _png(path: Path, a: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path), a)


def make_folder(d: Path, seq: int, n: int) -> None:
    for k in range(n):
        _png(d / "depth" / f"{k:06d}.png", _depth(seq, k))
        _png(d / "rgb" / f"{k:06d}.png", _colour(seq, k))


def make_tum(d: Path, seq: int, n: int, associations: bool) -> None:
    dl, rl, al = ["# depth maps", "# timestamp filename"], ["# color images"], []
    for k in range(n):
        tr, td = 1305031102.0 + 0.033 * k, 1305031102.0 + 0.033 * k + 0.004
        _png(d / "depth" / f"{td:.6f}.png", _depth(seq, k))
        _png(d / "rgb" / f"{tr:.6f}.png", _colour(seq, k))
        dl.append(f"{td:.6f} depth/{td:.6f}.png")
        rl.append(f"{tr:.6f} rgb/{tr:.6f}.png")
        al.append(f"{tr:.6f} rgb/{tr:.6f}.png {td:.6f} depth/{td:.6f}.png")
    rl.append(f"{1305031102.0 + 0.033 * n + 0.5:.6f} rgb/extra.png")  # a colour frame with no depth: ignored
    _png(d / "rgb" / "extra.png", _colour(seq, 99))
    (d / "depth.txt").write_text("\n".join(dl) + "\n")
    (d / "rgb.txt").write_text("\n".join(rl) + "\n")
    if associations:
        (d / "associations.txt").write_text("\n".join(al) + "\n")


def make_index(d: Path, seq: int, n: int) -> None:
    lines = []
    for k in range(n):
        _png(d / "depth" / f"{k:05d}.png", _depth(seq, k))
        _png(d / "rgb" / f"{k:05d}.png", _colour(seq, k))
        lines.append(f"{k:05d} depth/{k:05d}.png rgb/{k:05d}.png 0,0.1,0.2")
    (d / "index.txt").write_text("\n".join(lines) + "\n")


@pytest.fixture(scope="module")
def root(tmp_path_factory) -> Path:
    """Three recordings, one per layout family: a depth/+rgb/ folder, TUM lists, an index.txt (5, 4, 3 frames)."""
    r = tmp_path_factory.mktemp("recordings")
    make_folder(r / "a_folder", 0, COUNTS[0])
    make_tum(r / "b_tum", 1, COUNTS[1], associations=False)
    make_index(r / "nested" / "c_index", 2, COUNTS[2])
    return r


# ---- test restorers (module level: picklable for pools, importable by the torchrun script) ---------------------

class RunningMean:
    """A stateful, deterministic restorer: holes take the previous output, the rest the mean of the frame and the
    previous output, plus a colour term (so a lost colour or a wrong state shows in the bits)."""

    def __init__(self):
        self.prev = None
        self.log = os.environ.get("RECORDINGS_TEST_LOG")
        self.kill_after = int(os.environ.get("RECORDINGS_TEST_KILL_AFTER", "0"))
        self.kill_rank = os.environ.get("RECORDINGS_TEST_KILL_RANK", os.environ.get("RANK", "0"))
        self.steps = 0

    def reset(self):
        self.prev = None

    def step(self, depth, rgb):
        if self.kill_after and self.steps >= self.kill_after and self.kill_rank == os.environ.get("RANK", "0"):
            os._exit(9)  # a killed process: no cleanup, no exception handler
        self.steps += 1
        if self.log:
            with open(Path(self.log) / f"{os.getpid()}.txt", "a") as f:
                f.write(f"{int(depth[0, 0])}\n")
        d = depth.astype(np.int64)
        colour = 0 if rgb is None else int(round(float(rgb.mean()) * 10))
        out = d.copy() if self.prev is None else np.where(d > 0, (d + self.prev) // 2, self.prev)
        out = out + colour
        self.prev = out
        return out.astype(depth.dtype)


class Broken:
    """A restorer that fails on one frame (pixel (0,0) == 2001: the second sequence's frame 1)."""

    stateful = False

    def reset(self):
        pass

    def step(self, depth, rgb):
        if int(depth[0, 0]) == 2001:
            raise ValueError("this frame is bad")
        return depth


def _records(out: Path) -> list[dict]:
    """The manifest without the timing (the only field that differs between equal runs)."""
    return [{k: v for k, v in r.items() if k != "seconds"} for r in read_manifest(out / "manifest.jsonl")]


def _outputs(out: Path) -> dict[str, bytes]:
    return {p.relative_to(out).as_posix(): p.read_bytes() for p in sorted(out.rglob("*.png"))}


@pytest.fixture(scope="module")
def reference(root, tmp_path_factory) -> Path:
    """An uninterrupted one-process run with RunningMean."""
    out = tmp_path_factory.mktemp("reference") / "out"
    s = restore_dataset(root, out, restorer=RunningMean, threads=1, progress=False)
    assert s.ok and s.written == sum(COUNTS) and s.skipped == 0 and s.failed == 0
    return out


def _expected_running_mean(seq: int, n: int) -> list[np.ndarray]:
    prev, outs = None, []
    for k in range(n):
        d = _depth(seq, k).astype(np.int64)
        rgb = _colour(seq, k)[..., ::-1].astype(np.float32) / 255  # as read_rgb
        colour = int(round(float(rgb.mean()) * 10))
        out = d.copy() if prev is None else np.where(d > 0, (d + prev) // 2, prev)
        prev = out = out + colour
        outs.append(out.astype(np.uint16))
    return outs


# ---- discovery -----------------------------------------------------------------------------------------------

def test_discovers_each_layout_in_order(root):
    seqs = discover_recordings(root)
    assert [(s.name, s.layout, len(s.frames)) for s in seqs] == [
        ("a_folder", "folder", 5), ("b_tum", "tum-lists", 4), ("nested/c_index", "index", 3)]
    for s in seqs:
        assert [f.index for f in s.frames] == list(range(len(s.frames)))
        for f in s.frames:
            assert f.depth_path.is_file() and f.rgb_path.is_file()
            # the pairing is right: the colour file belongs to the depth frame
            seq = ["a_folder", "b_tum", "nested/c_index"].index(s.name)
            assert int(cv2.imread(str(f.depth_path), cv2.IMREAD_UNCHANGED)[0, 0]) == 1000 * (seq + 1) + f.index
            assert np.array_equal(cv2.imread(str(f.rgb_path)), _colour(seq, f.index))
    tum = seqs[1]
    assert tum.frames[0].timestamp == pytest.approx(1305031102.004) and tum.unmatched == 0
    assert seqs[0].frames[0].timestamp is None
    # one recording given directly is one sequence named after its folder
    one = discover_recordings(root / "nested" / "c_index")
    assert [(s.name, len(s.frames)) for s in one] == [("c_index", 3)]


def test_tum_associations_and_tolerance(tmp_path):
    make_tum(tmp_path / "assoc", 4, 3, associations=True)
    (s,) = discover_recordings(tmp_path / "assoc")
    assert s.layout == "tum-associations" and len(s.frames) == 3
    assert all(f.depth_path.parent.name == "depth" and f.rgb_path.parent.name == "rgb" for f in s.frames)
    # depth.txt + rgb.txt with a tolerance below the 4 ms offset: no pair, a clear error
    make_tum(tmp_path / "lists", 4, 3, associations=False)
    with pytest.raises(UsageError, match="within 0.001 s"):
        discover_recordings(tmp_path / "lists", max_time_difference=0.001)
    # associate.py's greedy rule: closest pairs first, each colour frame used once
    assert associate_timestamps([0.0, 0.01, 1.0], [0.005, 0.012, 5.0], 0.02) == [(0, 0), (1, 1)]
    assert associate_timestamps([0.0, 0.004], [0.003], 0.02) == [(1, 0)]


def test_tum_unmatched_depth_frames_are_counted(tmp_path):
    make_tum(tmp_path, 5, 3, associations=False)
    with open(tmp_path / "depth.txt", "a") as f:
        f.write("1305031200.000000 depth/000000.png\n")  # a depth frame 100 s from any colour frame
    _png(tmp_path / "depth" / "000000.png", _depth(5, 9))
    (s,) = discover_recordings(tmp_path)
    assert len(s.frames) == 3 and s.unmatched == 1


@pytest.mark.parametrize("listing, text, message", [
    ("index.txt", "00000 depth/00000.png\n", "expected 'id depth/<file> rgb/<file>"),
    ("index.txt", "00000 depth/missing.png rgb/00000.png\n", "does not exist"),
    ("index.txt", "0 depth/00000.png rgb/00000.png\n1 depth/00000.png rgb/00000.png\n",
     r"line 2 lists the depth file .* again \(first at .*line 1\)"),
    ("associations.txt", "1.0 a/1.png 1.0 b/1.png\n", "cannot tell which"),
    ("associations.txt", "x depth/00000.png 1.0 rgb/00000.png\n", "expected a timestamp"),
])
def test_malformed_listings_name_the_file_and_line(tmp_path, listing, text, message):
    make_index(tmp_path, 0, 1)
    (tmp_path / "index.txt").unlink()
    if listing == "associations.txt":
        _png(tmp_path / "a" / "1.png", _depth(0, 0))
        _png(tmp_path / "b" / "1.png", _depth(0, 0))
    (tmp_path / listing).write_text(text)
    with pytest.raises(UsageError, match=message) as e:
        discover_recordings(tmp_path)
    assert listing in str(e.value)


def test_no_recordings_is_a_clear_error(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(UsageError, match="no recordings under .*associations.txt"):
        discover_recordings(tmp_path)
    with pytest.raises(UsageError, match="does not exist"):
        discover_recordings(tmp_path / "nope")


def test_real_sequences_are_discovered():
    from torch_depth_sr._data_root import require_data_root

    data = require_data_root("real_sequences")
    seqs = discover_recordings(data / "real_sequences")
    assert [(s.name, s.layout, len(s.frames)) for s in seqs] == [
        ("realsense_d435_t265_desk", "index", 150), ("realsense_static_tabletop", "index", 207)]
    f = seqs[1].frames[0]
    assert f.depth_path.name == "00000.png" and f.rgb_path.name == "00000.jpg"


def test_real_sequences_restore_as_16_bit_millimetres(tmp_path):
    """Two frames of each real sequence through the plumbing (a cheap restorer): 16-bit PNG out, same size."""
    from torch_depth_sr._data_root import require_data_root

    data = require_data_root("real_sequences")
    seqs = [Sequence(s.name, s.frames[:2], s.folder, s.layout) for s in discover_recordings(data / "real_sequences")]
    s = restore_dataset(seqs, tmp_path / "out", restorer=RunningMean, progress=False)
    assert s.ok and s.written == 4
    for seq in seqs:
        for f in seq.frames:
            a = cv2.imread(str(tmp_path / "out" / seq.output_name(f)), cv2.IMREAD_UNCHANGED)
            b = cv2.imread(str(f.depth_path), cv2.IMREAD_UNCHANGED)
            assert a.dtype == np.uint16 and a.shape == b.shape


# ---- one process -------------------------------------------------------------------------------------------

def test_manifest_and_outputs(root, reference):
    recs = read_manifest(reference / "manifest.jsonl")
    assert [(r["sequence"], r["index"]) for r in recs] == [
        (name, k) for name, n in zip(("a_folder", "b_tum", "nested/c_index"), COUNTS) for k in range(n)]
    assert set(recs[0]) == {"sequence", "index", "timestamp", "depth", "rgb", "output", "status", "seconds",
                            "attempt", "error"}
    assert all(r["status"] == "ok" and r["error"] is None and r["attempt"] == 1 and r["seconds"] >= 0 for r in recs)
    r = recs[5]  # b_tum frame 0
    assert Path(r["depth"]).is_absolute() and r["depth"].endswith(".004000.png") and r["rgb"].endswith(".000000.png")
    assert r["output"] == f"b_tum/depth/{Path(r['depth']).name}" and r["timestamp"] == pytest.approx(1305031102.004)
    # every frame once, nothing else written (no shards or temporary files left)
    assert sorted(p.name for p in reference.iterdir()) == ["a_folder", "b_tum", "manifest.jsonl", "nested"]
    assert sorted(_outputs(reference)) == sorted(r["output"] for r in recs)
    assert not list(reference.rglob(".*"))
    # the values: the restorer's state carried frame to frame within each sequence, reset between them
    for seq, (name, n) in enumerate(zip(("a_folder", "b_tum", "nested/c_index"), COUNTS)):
        got = [cv2.imread(str(reference / r["output"]), cv2.IMREAD_UNCHANGED) for r in recs if r["sequence"] == name]
        assert all(np.array_equal(g, e) for g, e in zip(got, _expected_running_mean(seq, n)))
    # the inputs are untouched
    assert np.array_equal(cv2.imread(str(root / "a_folder/depth/000000.png"), cv2.IMREAD_UNCHANGED), _depth(0, 0))


def test_never_overwrites_without_asking(root, reference, tmp_path):
    before = _outputs(reference)
    with pytest.raises(UsageError, match="holds the manifest of an earlier run .*--resume"):
        restore_dataset(root, reference, restorer=RunningMean, progress=False)
    # resuming a finished run writes nothing
    s = restore_dataset(root, reference, restorer=RunningMean, resume=True, progress=False)
    assert s.ok and s.written == 0 and s.skipped == sum(COUNTS)
    assert _outputs(reference) == before
    # outputs that no manifest records are never replaced without --overwrite
    out = tmp_path / "foreign"
    _png(out / "a_folder" / "depth" / "000002.png", np.zeros((4, 4), np.uint16))
    with pytest.raises(UsageError, match="already exists and no manifest .*--overwrite"):
        restore_dataset(root, out, restorer=RunningMean, resume=True, progress=False)
    assert not (out / "manifest.jsonl").exists()
    s = restore_dataset(root, out, restorer=RunningMean, overwrite=True, threads=1, progress=False)
    assert s.ok and _outputs(out) == before
    # the output folder can never be the recordings (an output would replace an input)
    with pytest.raises(UsageError, match="would replace the input"):
        restore_dataset(root / "a_folder", root, restorer=RunningMean, overwrite=True, progress=False)


def test_failed_frames_are_recorded_and_retried(root, tmp_path):
    out = tmp_path / "out"
    s = restore_dataset(root, out, restorer=Broken, progress=False)
    assert not s.ok and s.failed == 1 and s.missing == 1 and s.written == sum(COUNTS) - 1
    (bad,) = [r for r in read_manifest(out / "manifest.jsonl") if r["status"] == "failed"]
    assert (bad["sequence"], bad["index"]) == ("b_tum", 1) and "this frame is bad" in bad["error"]
    assert bad["depth"] in bad["error"] and not (out / bad["output"]).exists()
    s = restore_dataset(root, out, restorer=FrameByFrameIdentity, resume=True, progress=False)
    assert s.ok and s.written == 1 and s.skipped == sum(COUNTS) - 1
    r = [r for r in read_manifest(out / "manifest.jsonl") if r["index"] == 1 and r["sequence"] == "b_tum"]
    assert [(x["status"], x["attempt"]) for x in r] == [("ok", 2)]


class FrameByFrameIdentity:
    stateful = False

    def reset(self):
        pass

    def step(self, depth, rgb):
        return depth


def test_resume_after_a_killed_process_is_bit_identical(root, reference, tmp_path):
    """A process killed (os._exit) after 6 frames, mid-sequence; a partial manifest line; then --resume: the same
    manifest and the same bytes as the uninterrupted run."""
    out = tmp_path / "out"
    script = (f"import sys; sys.path.insert(0, {str(TESTS)!r}); from test_recordings import RunningMean; "
              "from torch_depth_sr.recordings import restore_dataset; "
              f"restore_dataset({str(root)!r}, {str(out)!r}, restorer=RunningMean, threads=1, progress=False)")
    env = {**os.environ, "RECORDINGS_TEST_KILL_AFTER": "6", "OMP_NUM_THREADS": "1"}
    p = subprocess.run([sys.executable, "-c", script], env=env, cwd=REPO, capture_output=True, text=True,
                       timeout=300)
    assert p.returncode == 9, p.stderr[-2000:]
    shard = shard_path(out, 0)
    assert len(read_manifest(shard)) == 6 and not (out / "manifest.jsonl").exists()
    with open(shard, "ab") as f:
        f.write(b'{"sequence": "b_tum", "index": 1, "sta')  # a line cut by the kill
    s = restore_dataset(root, out, restorer=RunningMean, resume=True, threads=1, progress=False)
    assert s.ok and s.written == sum(COUNTS) - 6 and s.skipped == 6
    assert _records(out) == _records(reference)
    assert _outputs(out) == _outputs(reference)
    assert not shard.exists()


def test_unrecorded_output_of_a_killed_run_is_rewritten(root, reference, tmp_path):
    """Killed between writing a frame and recording it: --resume restores it again (same bytes)."""
    import shutil

    out = tmp_path / "out"
    shutil.copytree(reference, out)
    lines = (out / "manifest.jsonl").read_bytes().splitlines(keepends=True)
    (out / "manifest.jsonl").write_bytes(b"".join(lines[:-1]) + lines[-1][:20])
    s = restore_dataset(root, out, restorer=RunningMean, resume=True, threads=1, progress=False)
    assert s.ok and s.written == 1 and _records(out) == _records(reference) and _outputs(out) == _outputs(reference)


def test_manifest_reader_tolerates_partial_lines(tmp_path):
    p = tmp_path / "m.jsonl"
    with ManifestWriter(p) as w:
        w.append({"sequence": "s", "index": 0, "status": "ok", "attempt": 1})
    with open(p, "ab") as f:
        f.write(b'{"sequence": "s", "ind')
    with ManifestWriter(p) as w:  # the next writer starts on a new line
        w.append({"sequence": "s", "index": 1, "status": "failed", "attempt": 1})
    assert [r["index"] for r in read_manifest(p)] == [0, 1]
    # merging keeps the highest attempt of each frame
    with ManifestWriter(shard_path(tmp_path, 1)) as w:
        w.append({"sequence": "s", "index": 1, "status": "ok", "attempt": 2})
    p.rename(tmp_path / "manifest.jsonl")
    path, recs = merge_manifest(tmp_path)
    assert [(r["index"], r["status"]) for r in recs] == [(0, "ok"), (1, "ok")] and not shard_path(tmp_path, 1).exists()


def test_process_pool_matches_one_process(root, reference, tmp_path):
    out = tmp_path / "out"
    s = restore_dataset(root, out, restorer=RunningMean, workers=2, threads=1, progress=False)
    assert s.ok and s.written == sum(COUNTS)
    assert _records(out) == _records(reference) and _outputs(out) == _outputs(reference)


def test_bad_arguments(root, tmp_path):
    with pytest.raises(UsageError, match="workers must be a whole number"):
        restore_dataset(root, tmp_path, workers=-1)
    with pytest.raises(UsageError, match="restorer must be a callable"):
        restore_dataset(root, tmp_path, restorer=RunningMean())
    with pytest.raises(UsageError, match="is a file"):
        (tmp_path / "f").write_text("")
        restore_dataset(root, tmp_path / "f")


# ---- the command line and the real model --------------------------------------------------------------------

def test_cli_restores_recordings_like_restore_depth(root, tmp_path, capsys):
    """The default model frame by frame: each output equals restore_depth on that frame (and `restore` on it)."""
    import torch

    from torch_depth_sr import DepthRestorer, restore_depth
    from torch_depth_sr.datasets.io import read_depth_stored, read_rgb

    out = tmp_path / "out"
    assert main(["restore", "--recordings", str(root / "nested"), str(out), "--threads", "1"]) == 0
    line = capsys.readouterr().out.strip()
    assert line.startswith("restored 1 sequence (3 frames)") and "3 written, 0 already done, 0 failed" in line
    (seq,) = discover_recordings(root / "nested")
    model = None  # the CLI without --preset or --pretrained runs restore_depth's default
    old = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        for f in seq.frames:
            rgb = torch.from_numpy(read_rgb(f.rgb_path)).permute(2, 0, 1)[None]
            with torch.no_grad():
                want = restore_depth(read_depth_stored(f.depth_path), rgb, model=model)
            got = cv2.imread(str(out / seq.output_name(f)), cv2.IMREAD_UNCHANGED)
            assert got.dtype == np.uint16 and np.array_equal(got, want)
    finally:
        torch.set_num_threads(old)
    # run again: refused in one line, nothing written; --resume: nothing to do
    assert main(["restore", "--recordings", str(root / "nested"), str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--resume" in err
    assert main(["restore", "--recordings", str(root / "nested"), str(out), "--resume"]) == 0
    assert "0 written, 3 already done" in capsys.readouterr().out


@pytest.mark.parametrize("argv, message", [
    (["-o", "x"], "does not take -o"),
    (["--skip-existing"], "use --resume"),
    (["--in-place"], "--in-place"),
    (["--pretrained", "nope"], "no pretrained parameters named 'nope'"),
    (["--preset", "nope"], "--preset 'nope': unknown preset 'nope'"),
    (["--threads", "0"], "expected a whole number >= 1"),
    (["--max-time-difference", "-1"], "seconds > 0"),
])
def test_cli_mistakes_are_one_line(root, tmp_path, capsys, argv, message):
    code = main(["restore", "--recordings", str(root), str(tmp_path / "out")] + argv)
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and message in err, err
    assert not (tmp_path / "out").exists()


def test_frame_by_frame_adapter_is_restore_depth():
    from torch_depth_sr import DepthRestorer, restore_depth

    import torch

    d = _depth(0, 0)
    rgb = torch.from_numpy(_colour(0, 0).astype(np.float32) / 255).permute(2, 0, 1)
    m = DepthRestorer(num_layers=1)
    r = FrameByFrame(m)
    r.reset()
    assert np.array_equal(r.step(d, rgb), restore_depth(d, rgb[None], model=m))
    assert PretrainedRestorer("denoise")().model.config == DepthRestorer.from_pretrained("denoise").config
    assert PretrainedRestorer(preset="fast")().model.config == DepthRestorer.from_preset("fast").config


def test_frame_by_frame_without_a_model_runs_restore_depths_default():
    """No model named: each frame gets what restore_depth runs without one (the default tier to denoise), not the
    frozen full model."""
    from torch_depth_sr import DepthRestorer, restore_depth

    import torch

    d = _depth(0, 0)
    rgb = torch.from_numpy(_colour(0, 0).astype(np.float32) / 255).permute(2, 0, 1)
    r = PretrainedRestorer()()
    assert r.model is None
    got = r.step(d, rgb)
    assert np.array_equal(got, restore_depth(d, rgb[None]))
    assert np.array_equal(got, restore_depth(d, rgb[None], model=DepthRestorer.from_preset("default")))


# ---- torchrun ---------------------------------------------------------------------------------------------------

def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _torchrun(script: Path, env: dict, timeout: int = 300) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-m", "torch.distributed.run", "--nproc-per-node", "2", "--master-addr", "127.0.0.1",
           "--master-port", str(_free_port()), str(script)]
    return subprocess.run(cmd, env={**os.environ, "OMP_NUM_THREADS": "1", **env}, cwd=REPO, capture_output=True,
                          text=True, timeout=timeout)


def _torchrun_script(tmp_path: Path, root: Path, out: Path) -> Path:
    """Each rank writes its summary to ``<tmp_path>/summaries/rank<R>.json`` (not stdout: two processes sharing
    torchrun's pipe can lose a buffered line on a loaded machine)."""
    script = tmp_path / f"run_{out.name}.py"
    summaries = tmp_path / "summaries"
    summaries.mkdir(exist_ok=True)
    script.write_text(
        f"import json, os, sys\nsys.path.insert(0, {str(TESTS)!r})\nfrom test_recordings import RunningMean\n"
        "from torch_depth_sr.recordings import restore_dataset\n"
        f"s = restore_dataset({str(root)!r}, {str(out)!r}, restorer=RunningMean, resume=True, threads=1, "
        "progress=False)\n"
        "summary = json.dumps({'written': s.written, 'skipped': s.skipped, 'frames': s.frames, "
        "'processes': s.processes})\n"
        f"path = os.path.join({str(summaries)!r}, 'rank' + os.environ.get('RANK', '0') + '.json')\n"
        "with open(path, 'w') as f:\n    f.write(summary)\n    f.flush()\n    os.fsync(f.fileno())\n")
    return script


def _summaries(tmp_path: Path) -> list:
    return [json.loads(p.read_text()) for p in sorted((tmp_path / "summaries").glob("rank*.json"))]


def test_torchrun_two_processes_write_every_frame_once_bit_identical(root, reference, tmp_path):
    """Two gloo ranks: each frame restored by exactly one rank; the outputs and the manifest are those of the
    one-process run."""
    out, log = tmp_path / "out", tmp_path / "log"
    log.mkdir()
    p = _torchrun(_torchrun_script(tmp_path, root, out), {"RECORDINGS_TEST_LOG": str(log)})
    assert p.returncode == 0, p.stderr[-3000:]
    summaries = _summaries(tmp_path)
    assert len(summaries) == 2 and all(s == summaries[0] for s in summaries)
    assert summaries[0]["processes"] == 2 and summaries[0]["written"] == sum(COUNTS)
    # every frame stepped exactly once, by two different processes (rank 0: 5 frames, rank 1: 4 + 3)
    logs = {p.name: p.read_text().split() for p in log.iterdir()}
    stepped = sorted(int(v) for vs in logs.values() for v in vs)
    assert sorted(len(v) for v in logs.values()) == [5, 7]
    assert stepped == sorted(1000 * (s + 1) + k for s, n in enumerate(COUNTS) for k in range(n))
    assert _records(out) == _records(reference) and _outputs(out) == _outputs(reference)
    assert sorted(p.name for p in out.iterdir()) == ["a_folder", "b_tum", "manifest.jsonl", "nested"]


def test_torchrun_killed_rank_resumes_to_the_same_manifest(root, reference, tmp_path):
    """Rank 1 dies (os._exit) after its first 2 frames and torchrun stops the group; the same command again
    finishes the run: the manifest and the outputs are those of an uninterrupted run."""
    out = tmp_path / "out"
    script = _torchrun_script(tmp_path, root, out)
    p = _torchrun(script, {"RECORDINGS_TEST_KILL_AFTER": "2", "RECORDINGS_TEST_KILL_RANK": "1"})
    assert p.returncode != 0
    assert not (out / "manifest.jsonl").exists() and len(read_manifest(shard_path(out, 1))) == 2
    for old in (tmp_path / "summaries").glob("rank*.json"):
        old.unlink()
    p = _torchrun(script, {})  # the same command again
    assert p.returncode == 0, p.stderr[-3000:]
    summary = _summaries(tmp_path)[0]
    assert summary["skipped"] >= 2 and summary["skipped"] + summary["written"] == sum(COUNTS)
    assert _records(out) == _records(reference) and _outputs(out) == _outputs(reference)


@pytest.mark.parametrize("flag", ["--stream", "--resume", "--max-time-difference 0.05"])
def test_recordings_only_flags_without_recordings_are_usage_errors(tmp_path, capsys, flag):
    depth = tmp_path / "d.png"
    cv2.imwrite(str(depth), _depth(0, 0))
    code = main(["restore", str(depth), "-o", str(tmp_path / "out.png"), *flag.split()])
    flag = flag.split()[0]
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and f"{flag} applies only with --recordings" in err, err
    assert not (tmp_path / "out.png").exists()
