"""`torch-depth-sr warmup`: the numba kernels compiled ahead of the first forward, once; the first-compile notice.

Behaviour only (numba's compile events, its cache hits, the dispatchers' signatures), never seconds: a busy CI
machine compiles at any speed.
"""
import logging
import os
import re
import subprocess
import sys
import warnings

import pytest
import torch

pytest.importorskip("numba")

from torch_depth_sr import native  # noqa: E402
from torch_depth_sr.warmup import warmup  # noqa: E402
from torch_depth_sr.cli import main  # noqa: E402

pytestmark = pytest.mark.skipif(native.numba_disabled(), reason="TORCH_DEPTH_SR_NO_NUMBA is set")


class _Compiles:
    """Names of this package's numba functions compiled (not loaded from the cache) inside the ``with`` block."""

    def __enter__(self):
        from numba.core import event

        names = self.names = []

        class _L(event.Listener):
            def on_start(self, ev):
                if native._ours(ev):
                    names.append(ev.data["dispatcher"].py_func.__qualname__)

            def on_end(self, ev):
                pass

        self._cm = event.install_listener("numba:compile", _L())
        self._cm.__enter__()
        return self

    def __exit__(self, *exc):
        self._cm.__exit__(*exc)


def test_warmup_leaves_nothing_for_the_forward_to_compile(scene):
    from torch_depth_sr import DepthRestorer

    warmup()  # compiles, or loads what an earlier process compiled
    sigs = native.compiled_signatures()
    for kernel in ("block_matching.cpu_exact._band", "block_matching.cpu_exact._finalize",
                   "block_matching.refine_cpu._refine", "edge_snap_kernel._sided", "edge_snap_kernel._refit",
                   "fill_kernel._pixels", "nonlocal_kernel._pixels", "singular_kernel._pixels",
                   "singular_kernel._agreeing", "singular_kernel._support_rule"):
        held = " ".join(sigs.get(kernel, []))
        assert "float32" in held and "float64" in held, (kernel, sigs.get(kernel))
    again = warmup()
    assert again["compiled"] == 0 and again["loaded"] == 0  # idempotent: all in memory already
    with _Compiles() as c:
        for dt in (torch.float32, torch.float64):
            y, rgb = scene["depth"].to(dt), scene["rgb"].to(dt)
            DepthRestorer()(y, rgb)
            DepthRestorer.from_preset("fast")(y, rgb)
    assert c.names == []


def _warmup_child(cache, *args):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    env.pop("TORCH_DEPTH_SR_NO_NUMBA", None)
    out = subprocess.run([sys.executable, "-m", "torch_depth_sr.cli", "warmup", *args], env=env, capture_output=True,
                         text=True, timeout=900)
    assert out.returncode == 0, out.stderr[-2000:]
    found = re.search(r"(\d+) kernel signature\(s\) compiled, (\d+) loaded from the cache", out.stdout)
    assert found, out.stdout
    return int(found.group(1)), int(found.group(2)), out


def test_warmup_fills_the_cache_a_second_process_only_loads(tmp_path):
    """An empty cache (NUMBA_CACHE_DIR): the first run compiles, a second process compiles nothing and loads."""
    compiled, loaded, out = _warmup_child(tmp_path, "--dtype", "float32")
    assert compiled > 0 and loaded == 0
    assert str(tmp_path) in out.stdout and "float32" in out.stdout and "float64" not in out.stdout
    assert "compiling the numba CPU kernels on their first use" not in out.stderr  # warmup says it its own way
    compiled2, loaded2, _ = _warmup_child(tmp_path, "--dtype", "float32")
    assert compiled2 == 0 and loaded2 > 0


def test_first_compilation_says_so_once_on_the_logger_not_as_a_warning(monkeypatch, caplog):
    import numba

    native.cpu_kernel("singular_kernel", "singular_rounds_cpu")  # the notice's listener is installed once
    monkeypatch.setitem(native._NOTICE, "given", False)

    def probe(a, b):
        return a + b

    probe.__module__ = "torch_depth_sr.probe"  # compiled as if it were one of the package's kernels
    probe = numba.njit(probe)
    with caplog.at_level(logging.WARNING, logger="torch_depth_sr"), warnings.catch_warnings():
        warnings.simplefilter("error")  # a notice through warnings would raise inside numba's compiler here
        assert probe(1, 2) == 3
        assert probe(1.5, 2.0) == 3.5  # a second compilation: no second line
    lines = [r.getMessage() for r in caplog.records if "compiling the numba CPU kernels" in r.getMessage()]
    assert len(lines) == 1 and "torch-depth-sr warmup" in lines[0]


def test_warmup_without_numba_kernels_is_a_quiet_no_op(monkeypatch, capsys):
    monkeypatch.setenv("TORCH_DEPTH_SR_NO_NUMBA", "1")
    assert main(["warmup"]) == 0
    assert "nothing to compile" in capsys.readouterr().out


def test_warmup_without_numba_is_a_one_line_error():
    child = ("import sys; sys.modules['numba'] = None  # as where numba is missing or broken\n"
             "from torch_depth_sr.cli import main; sys.exit(main(['warmup']))")
    env = {k: v for k, v in os.environ.items() if k != "TORCH_DEPTH_SR_NO_NUMBA"}
    out = subprocess.run([sys.executable, "-c", child], env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 1
    assert out.stderr.count("\n") == 1 and "no kernels to compile" in out.stderr and "Traceback" not in out.stderr


def test_warmup_refuses_an_unknown_dtype_in_one_line(capsys):
    assert main(["warmup", "--dtype", "float16"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "invalid choice" in err


@pytest.mark.parametrize("threads", [1, 2])
def test_run_tasks_keeps_the_order_and_raises_a_task_error(threads):
    old = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        assert native.run_tasks(lambda i: i * i, 7) == [0, 1, 4, 9, 16, 25, 36]
        assert native.run_tasks(lambda i: i, 0) == []

        def fail(i):
            if i == 3:
                raise ValueError("task 3")
            return i

        with pytest.raises(ValueError, match="task 3"):
            native.run_tasks(fail, 5)
    finally:
        torch.set_num_threads(old)


_MODEL_WARMUP = """
import torch
from numba.core import event
from torch_depth_sr import DepthRestorer
from torch_depth_sr.datasets.synthetic import make_scene
from torch_depth_sr.degradations import SensorDegradation
from torch_depth_sr.native import compiled_signatures
from torch_depth_sr.warmup import warmup

model = DepthRestorer.from_preset("fast")
report = warmup(dtypes=(torch.float32,), model=model)
held = {k for k, v in compiled_signatures().items() if v}
seen = []


class Listen(event.Listener):
    def on_start(self, ev):
        seen.append(ev)

    def on_end(self, ev):
        pass


frame = SensorDegradation(seed=1)(make_scene(96, 128, seed=3))
with event.install_listener("numba:compile", Listen()), torch.no_grad():
    model(frame["depth"][None], frame["rgb"][None])
grew = {k for k, v in compiled_signatures().items() if v} - held
print("|".join([report["steps"][0][1], str(len(held)), str(sorted(grew)), str(len(seen)), str(sorted(held))]))
"""


def test_warmup_with_a_model_loads_what_its_forward_calls(tmp_path):
    """``warmup(model=...)`` in a fresh process (the shared cache): the model's forward on another frame compiles
    and loads nothing more, and the stream's kernels, which the forward never calls, are not loaded."""
    script = tmp_path / "model_warmup.py"
    script.write_text(_MODEL_WARMUP)
    env = {k: v for k, v in os.environ.items() if k != "TORCH_DEPTH_SR_NO_NUMBA"}
    out = subprocess.run([sys.executable, str(script)], env=env, capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr[-2000:]
    label, held, grew, compiled, names = out.stdout.strip().splitlines()[-1].split("|")
    assert label == "model forward" and int(held) > 0 and grew == "[]" and compiled == "0", out.stdout
    assert "singular_kernel._pixels" in names and "stream.change_kernel" not in names, names
