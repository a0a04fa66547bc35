"""Issue 27 item 6: the forward of every speed tier makes the host wait for the device nowhere.

A GPU path is checked on the CPU: ``TORCH_DEPTH_SR_DEVICE_PATH=1`` sends the CPU down the path every other device
takes (torch kernels instead of numba, no shortcut that reads a value on the host; :func:`torch_depth_sr.native.
host_path`). A dispatch mode records each operator that needs a value on the host (``_local_scalar_dense`` is what
``.item()``, ``bool(t)``, ``float(t)`` and ``.tolist()`` end in) or whose output shape depends on the values
(``nonzero``, boolean-mask indexing, ``unique``, ``masked_select``): either makes a GPU's host wait.
"""
from __future__ import annotations

import traceback

import pytest
import torch
from torch.overrides import TorchFunctionMode
from torch.utils._python_dispatch import TorchDispatchMode

from torch_depth_sr import DepthRestorer

aten = torch.ops.aten
# operators that read a value on the host, or whose output's shape depends on the values
SYNCING = {aten._local_scalar_dense.default, aten.is_nonzero.default, aten.item.default, aten.nonzero.default,
           aten.nonzero_static.default, aten.masked_select.default, aten._unique.default, aten._unique2.default,
           aten.unique_dim.default, aten.unique_consecutive.default, aten.equal.default, aten.allclose.default,
           aten.repeat_interleave.Tensor, aten.bincount.default}
_INDEX = {aten.index.Tensor, aten.index_put.default, aten.index_put_.default, aten._index_put_impl_.default}


def _bool_index(func, args) -> bool:
    """Indexing by a boolean mask (``t[mask]``, ``t[mask] = v``): the shape of the selection depends on the mask."""
    if func not in _INDEX or len(args) < 2:
        return False
    return any(isinstance(i, torch.Tensor) and i.dtype in (torch.bool, torch.uint8) for i in args[1] if i is not None)


# Tensor methods that copy to the host: on a CPU tensor they reach no operator above, so they are caught by name
COPIES = {torch.Tensor.tolist, torch.Tensor.numpy, torch.Tensor.cpu, torch.Tensor.__array__}


def _where() -> str:
    """The innermost frame of the package that called."""
    frames = [f for f in traceback.extract_stack() if "torch_depth_sr/" in f.filename and "/tests/" not in f.filename]
    return f"{frames[-1].filename.split('torch_depth_sr/')[-1]}:{frames[-1].lineno}" if frames else "?"


class _Copies(TorchFunctionMode):
    def __init__(self, found: list):
        super().__init__()
        self.found = found

    def __torch_function__(self, func, types, args=(), kwargs=None):
        if func in COPIES:
            self.found.append((func.__name__, _where()))
        return func(*args, **(kwargs or {}))


class _Operators(TorchDispatchMode):
    def __init__(self, found: list):
        super().__init__()
        self.found = found

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        if func in SYNCING or _bool_index(func, args):
            self.found.append((str(func), _where()))
        return func(*args, **(kwargs or {}))


class HostSyncs:
    """Records ``(operator or method, where)`` of everything inside it that makes a GPU's host wait (``where``: the
    innermost frame of this package)."""

    def __init__(self):
        self.found: list[tuple[str, str]] = []
        self._modes = (_Copies(self.found), _Operators(self.found))

    def __enter__(self):
        for m in self._modes:
            m.__enter__()
        return self

    def __exit__(self, *exc):
        for m in reversed(self._modes):
            m.__exit__(*exc)


def _sensor_like(b: int = 2, h: int = 40, w: int = 48):
    """Noisy depth with holes (zeros) and flying pixels (the edge steps act on such samples), and its colour."""
    from torch_depth_sr.datasets.synthetic import make_scene

    depth, rgb = [], []
    g = torch.Generator().manual_seed(6)
    for i in range(b):
        s = make_scene(h, w, seed=11 + i)
        y = s["gt"] + 2.0 * torch.randn(s["gt"].shape, generator=g)
        y[..., 8:13, 20:27] = 0  # a hole
        y[torch.rand(y.shape, generator=g) < 0.03] = 0  # scattered missing pixels
        fly = torch.rand(y.shape, generator=g) < 0.02
        y = torch.where(fly, y + 40 * torch.rand(y.shape, generator=g), y)  # outliers
        depth.append(y.clamp_min(0))
        rgb.append(s["rgb"])
    return torch.stack(depth), torch.stack(rgb)


@pytest.fixture
def device_path(monkeypatch):
    monkeypatch.setenv("TORCH_DEPTH_SR_DEVICE_PATH", "1")


@pytest.mark.parametrize("tier", ["fast", "default", "best"])
def test_the_forward_of_every_tier_has_no_host_sync_on_the_device_path(tier, device_path, monkeypatch):
    """As while a CUDA graph is captured (the inputs are not checked): nothing at all."""
    _no_value_checks(monkeypatch)
    model = DepthRestorer.from_preset(tier)
    depth, rgb = _sensor_like()
    with torch.no_grad(), HostSyncs() as rec:
        out = model(depth, rgb)
    assert torch.isfinite(out).all()
    assert rec.found == []


def _no_value_checks(monkeypatch):
    """As while a CUDA graph is captured: the inputs' values are not read (:func:`torch_depth_sr._inputs.
    _values_readable`)."""
    from torch_depth_sr import _inputs

    monkeypatch.setattr(_inputs, "_values_readable", lambda t: False)


@pytest.mark.parametrize("tier", ["fast", "default", "best"])
def test_the_forward_of_every_tier_reads_only_its_inputs_on_the_host(tier, device_path):
    """Outside a graph capture the only reads are the input checks, one per input (depth, colour)."""
    model = DepthRestorer.from_preset(tier)
    depth, rgb = _sensor_like()
    with torch.no_grad(), HostSyncs() as rec:
        model(depth, rgb)
    assert [where.split(":")[0] for _, where in rec.found] == ["_inputs.py", "_inputs.py"]


def test_the_detector_sees_a_sync_put_back(device_path, monkeypatch):
    """The test above would fail on a ``bool(t.any())`` in the forward (here: after the glitch test)."""
    import torch_depth_sr.observation as observation

    _no_value_checks(monkeypatch)
    plain = observation.implausible

    def asks(*args, **kwargs):
        out = plain(*args, **kwargs)
        bool(out.any())
        return out

    monkeypatch.setattr(observation, "implausible", asks)
    depth, rgb = _sensor_like(1, 24, 32)
    with torch.no_grad(), HostSyncs() as rec:
        DepthRestorer(num_layers=1)(depth, rgb)
    assert rec.found and {f for f, _ in rec.found} == {"aten._local_scalar_dense.default"}
    with HostSyncs() as rec:
        torch.arange(4.0)[torch.arange(4) > 1]
        torch.arange(4.0).tolist()
    assert [f for f, _ in rec.found] == ["aten.index.Tensor", "tolist"]


def test_a_stream_step_reads_the_device_only_where_it_spares_work(device_path):
    """Issue 28 on a GPU: a warm stream step (the module's forward, no details) makes the host wait only for the
    choices that spare work: whether to keep the scale policy (the share of static pixels), whether the kept matches'
    weights hold (the temperature), whether any pixel must be searched or get the later layers. Its statistics stay
    on the device unless asked for (``return_details``), and are then read at once. (Before: 19 reads a step, among
    them each statistic and ``info``'s figures.)"""
    from torch_depth_sr.stream import StreamRestorer, default_stream_model

    depth, rgb = _sensor_like()
    stream = StreamRestorer(default_stream_model())
    spare_work = {"stream/frame.py", "stream/matching.py", "stream/later_layers.py"}
    g = torch.Generator().manual_seed(0)
    with torch.no_grad():
        for t in range(4):
            noisy = torch.where(depth > 0, depth + 0.5 * torch.randn(depth.shape, generator=g), depth)
            with HostSyncs() as rec:
                stream(noisy, rgb)
            sites = [where.split(":")[0] for _, where in rec.found]
            assert sites[:2] == ["_inputs.py", "_inputs.py"], rec.found  # the input checks, as a frame on its own
            assert set(sites[2:]) <= spare_work and len(sites) <= 6, rec.found
        with HostSyncs() as rec:
            r = stream.step(noisy, rgb, return_details=True)
    stats = r.info["stream"]
    assert stats["frame"] == 4 and all(isinstance(v, float) for k, v in stats.items() if k != "frame")
    assert {"outliers_in_time", "held_out", "reused_matches", "held", "filled_from_past", "static"} <= set(stats)
    assert [f for f, where in rec.found if where.startswith("stream/frame.py")].count("tolist") == 1


def test_the_switch(monkeypatch):
    from torch_depth_sr.native import host_path

    assert host_path(torch.device("cpu")) and not host_path(torch.device("meta"))
    monkeypatch.setenv("TORCH_DEPTH_SR_DEVICE_PATH", "1")
    assert not host_path(torch.device("cpu"))


# ---- the device path gives the CPU path's values ---------------------------------------------------------------
def _both_paths(monkeypatch, run):
    """``run()`` on the CPU path and on the device path (both with the torch kernels: numba is the CPU's only)."""
    monkeypatch.setenv("TORCH_DEPTH_SR_NO_NUMBA", "1")
    monkeypatch.setenv("TORCH_DEPTH_SR_DEVICE_PATH", "0")
    cpu = run()
    monkeypatch.setenv("TORCH_DEPTH_SR_DEVICE_PATH", "1")
    return cpu, run()


def _assert_equal(a, b):
    a, b = (a if isinstance(a, (tuple, list)) else (a,)), (b if isinstance(b, (tuple, list)) else (b,))
    assert len(a) == len(b)
    for u, v in zip(a, b):
        assert u.dtype == v.dtype and u.shape == v.shape
        assert torch.equal(u, v), (u - v).abs().max()


@pytest.mark.parametrize("tier", ["fast", "default", "best"])
def test_every_tier_gives_the_same_output_on_both_paths(tier, monkeypatch):
    model = DepthRestorer.from_preset(tier)
    depth, rgb = _sensor_like()
    with torch.no_grad():
        cpu, dev = _both_paths(monkeypatch, lambda: model(depth, rgb))
    _assert_equal(cpu, dev)


def test_the_device_path_is_close_to_the_numba_kernels(monkeypatch):
    """Against the default CPU path (numba): block matching's float near-ties may pick other blocks."""
    model = DepthRestorer.from_preset("full")
    depth, rgb = _sensor_like()
    with torch.no_grad():
        cpu = model(depth, rgb)
        monkeypatch.setenv("TORCH_DEPTH_SR_DEVICE_PATH", "1")
        dev = model(depth, rgb)
    assert (cpu - dev).abs().mean() < 1e-3 * depth.max()


def _scales():
    g = torch.Generator().manual_seed(0)
    y = 100 + 5 * torch.randn(3, 1, 37, 41, generator=g)
    y[torch.rand(y.shape, generator=g) < 0.1] = 0
    yield y
    yield (y / 2).round() * 2 * (y > 0)  # on a grid of 2
    c = torch.full((2, 1, 20, 30), 7.0)
    c[:, :, :3] = 0
    yield c  # constant
    glitch = y.round().clamp_min(0)
    glitch[:, :, 5, 5] = 1e10
    yield glitch
    few = torch.zeros(2, 1, 10, 10)
    few[0, 0, 1, 1] = 3.0
    few[1, 0, :2, :3] = 5.0
    yield few
    yield 100 + torch.randn(2, 1, 70, 70, generator=g, dtype=torch.float64)


@pytest.mark.parametrize("y", list(_scales()), ids=["noisy", "grid", "constant", "glitch", "few", "float64"])
def test_the_scale_policy_is_the_same_on_both_paths(y, monkeypatch):
    from torch_depth_sr import noise

    obs = (y > 0).to(y.dtype)

    def run():
        step = noise.quantisation_step(y, obs)
        p = noise.sample_percentiles(y, obs)
        one = torch.ones(y.shape[0], dtype=y.dtype)
        return (noise.estimate_noise_sigma(y, obs), step, noise.quantisation_step(y, obs, integer_input=True), p,
                noise.implausible(y, obs, one, percentiles=p), noise.implausible(y, obs, one),
                *noise.depth_scale(y, obs, step=step, percentiles=p))

    cpu, dev = _both_paths(monkeypatch, run)
    _assert_equal(cpu, dev)


def test_the_fills_and_the_refit_are_the_same_on_both_paths(monkeypatch):
    from torch_depth_sr.edge_snap import refit_to_measurements
    from torch_depth_sr.fill import fill_holes, fill_holes_sided
    from torch_depth_sr.guided_filters import domain_transform_filter, joint_bilateral_filter

    depth, rgb = _sensor_like(2, 36, 44)
    m = (depth > 0).to(depth.dtype)
    x = fill_holes(depth, m)
    active = torch.tensor([True, False]).view(2, 1, 1, 1)

    def run():
        out = []
        for guide in (rgb, None):
            out += list(fill_holes_sided(depth, m, guide, kernel_size=7, passes=2, choice_sigma_space=1.5))
        out += [fill_holes(depth, m), domain_transform_filter(depth, rgb, m),
                domain_transform_filter(depth, rgb, m, fill_passes=0),
                joint_bilateral_filter(depth, rgb, m, kernel_size=5, fill_passes=1),
                refit_to_measurements(x, depth, m, rgb, radius=3, band=3.0, edge=4.0),
                refit_to_measurements(x, depth, m, rgb, radius=3, band=3.0, edge=4.0, active=active),
                refit_to_measurements(x, depth, m, rgb, radius=3, band=3.0, edge=1e9)]  # no edge
        return out

    cpu, dev = _both_paths(monkeypatch, run)
    _assert_equal(cpu, dev)


# ---- the GPU report --------------------------------------------------------------------------------------------
def test_the_gpu_report_without_a_gpu_says_so_in_one_line_and_exits_2(monkeypatch, capsys):
    from torch_depth_sr.evaluation import gpu_report

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert gpu_report.main(["--sizes", "48x64", "--batch", "1", "--out", "unused"]) == 2
    out = capsys.readouterr()
    assert out.out == gpu_report.NO_GPU + "\n" and out.err == ""


def test_the_gpu_report_without_a_gpu_as_a_command():
    import subprocess
    import sys

    from torch_depth_sr.evaluation import gpu_report

    if torch.cuda.is_available():
        pytest.skip("a GPU is here: the command would measure")
    done = subprocess.run([sys.executable, "-m", "torch_depth_sr.evaluation.gpu_report"], capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 2 and done.stdout == gpu_report.NO_GPU + "\n" and "Traceback" not in done.stderr


def test_the_gpu_report_table():
    from torch_depth_sr.evaluation.gpu_report import COLUMNS, format_table

    rows = [{"method": "default", "size": "480x640", "batch": 1, "ms_per_frame": 12.345, "peak_mb": 1500.0,
             "graph": "captured", "graph_ms_per_frame": 8.0, "graph_max_abs_diff": 0.0},
            {"method": "kornia-jbf9", "size": "480x640", "batch": 8, "ms_per_frame": 0.5, "peak_mb": 20.0},
            {"method": "stream-fast", "size": "480x640", "batch": 1, "ms_per_frame": 6.0, "step_vs_cold": 0.5},
            {"method": "best", "size": "1088x1376", "batch": 8, "error": "out of memory: CUDA"}]
    lines = format_table(rows).splitlines()
    assert lines[0] == "| " + " | ".join(COLUMNS + ["error"]) + " |" and len(lines) == 2 + len(rows)
    assert lines[2].startswith("| default | 480x640 | 1 | 12.3 |  | 1500 | captured | 8 | 0 |")
    assert lines[4].startswith("| stream-fast | 480x640 | 1 | 6 | 0.5 |")
    assert lines[5].endswith("| out of memory: CUDA |")
    assert format_table(rows[:1], header=False).count("\n") == 0


def test_the_gpu_reports_stream_step_feeds_new_frames_of_one_scene():
    """gpu_report.stream_step: its first call is the stream's cold frame (the per-frame model's output on that frame),
    later calls new noise on the same scene; drawing the noise on the CPU gives the same frames on the CPU."""
    from torch_depth_sr.evaluation import gpu_report, speed

    depth, rgb, gt = speed.make_inputs(24, 32, 1)
    model = DepthRestorer.from_preset("fast").eval()
    with torch.no_grad():
        step = gpu_report.stream_step(model, depth, rgb, gt)
        again = gpu_report.stream_step(model, depth, rgb, gt, noise_device="cpu")
        first, second = step(), step()
        assert torch.equal(first, again()) and torch.equal(second, again())
        frame = torch.where(depth <= 0, torch.zeros_like(depth),
                            (gt + 5.0 * torch.randn(depth.shape, generator=torch.Generator().manual_seed(1))
                             ).clamp_min(1.0))
        assert torch.equal(first, model(frame, rgb))
    assert not torch.equal(first, second)
