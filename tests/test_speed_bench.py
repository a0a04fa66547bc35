"""Smoke test of the speed track (``torch-depth-sr bench --track speed``) at a tiny size."""
import json
import types

import pytest
import torch

from torch_depth_sr.evaluation.speed import make_inputs, measure, run_speed


def test_make_inputs_shapes_and_holes():
    y, rgb, gt = make_inputs(32, 40, 2)
    assert y.shape == (2, 1, 32, 40) and rgb.shape == (2, 3, 32, 40) and gt.shape == y.shape
    assert bool((y == 0).any()) and bool((y[y > 0] >= 1).all())


def test_measure_full_reports_stages_and_cg():
    row = measure("full", 24, 32, 1, repeats=1)
    assert row["repeats"] == 1 and row["seconds"] > 0
    assert set(row["stages"]) == {"block_matching", "singular", "nonlocal", "cg", "rest", "total"}
    assert len(row["cg_iterations"]) == 8 and row["peak_mb"] is not None


def test_stream_row_times_its_step_against_a_cold_frame_in_turn():
    row = measure("stream-fast", 24, 32, 1, repeats=2)
    p = row["paired"]
    assert len(p["steps"]) == len(p["colds"]) == 2 and p["step"] > 0 and p["cold"] > 0
    assert p["ratio"] == pytest.approx(sum(a / b for a, b in zip(p["steps"], p["colds"])) / 2)  # median of two
    assert "paired" not in measure("fast", 24, 32, 1, repeats=1)


def test_moving_stream_row_steps_through_the_sequences_and_pairs_cold_frames_on_them():
    """``stream-fast-moving``: each call a new frame of the moving sequences (one per sample), the cold frames on the
    frame the step took, the rmse against that frame's ground truth (not the static inputs')."""
    from torch_depth_sr.evaluation import speed

    step = speed._make_runner("stream-fast-moving", "cpu", frames=3)
    y = torch.zeros(2, 1, 32, 40)
    out0, _ = step(y, None)
    first = step.frame[0].clone()
    out1, info = step(y, None)
    assert out1.shape == (2, 1, 32, 40) and not torch.equal(step.frame[0], first)  # the next frame
    assert info["stream"]["frame"] == 1 and step.gt.shape == (2, 1, 32, 40)
    row = measure("stream-fast-moving", 32, 40, 1, repeats=1)
    assert row["paired"]["step"] > 0 and row["paired"]["cold"] > 0
    assert 0 < row["rmse"] < 500  # mm against the sequence's own ground truth


@pytest.mark.parametrize("method", ["bm-exact", "bm-refine", "x0-filter"])
def test_measure_stage_rows(method):
    """The stage rows of the speed track (issue 13 item 5) run the model's own stage on its inputs."""
    row = measure(method, 24, 32, 1, repeats=1)
    assert row["repeats"] == 1 and row["seconds"] > 0 and "stages" not in row


def test_run_speed_in_process_writes_json_and_table(tmp_path, capsys):
    out = tmp_path / "speed.json"
    args = types.SimpleNamespace(json=str(out), device="cpu", sizes="24x32", batches="1", repeats=1,
                                 isolate=False, methods=["full", "jbf"])
    assert run_speed(args) == 0
    data = json.loads(out.read_text())
    assert {"torch", "kornia", "threads", "device", "loadavg_end"} <= set(data["metadata"])
    methods = [r["method"] for r in data["results"]]
    assert methods == ["full", "jbf", "kornia-jbf9"]  # the kornia reference is always added
    ref = [r for r in data["results"] if r["method"] == "kornia-jbf9"][0]
    assert ref["ratio_to_kornia_jbf9"] == pytest.approx(1.0)
    by = {r["method"]: r for r in data["results"]}  # full is the second reference: its own ratio is 1
    assert by["full"]["ratio_to_full"] == pytest.approx(1.0)
    assert by["jbf"]["ratio_to_full"] == pytest.approx(by["jbf"]["seconds"] / by["full"]["seconds"])
    printed = capsys.readouterr().out
    assert "x kornia9" in printed and "x full" in printed


def test_run_speed_without_full_has_no_ratio_to_it(tmp_path):
    out = tmp_path / "speed.json"
    args = types.SimpleNamespace(json=str(out), device="cpu", sizes="24x32", batches="1", repeats=1,
                                 isolate=False, methods=["jbf"])
    assert run_speed(args) == 0
    assert all(r["ratio_to_full"] is None for r in json.loads(out.read_text())["results"])


def test_run_speed_subprocess_one_method(tmp_path):
    out = tmp_path / "speed.json"
    args = types.SimpleNamespace(json=str(out), device="cpu", sizes="24x32", batches="1", repeats=1,
                                 methods=["kornia-jbf9"])  # isolate defaults to True
    assert run_speed(args) == 0
    (row,) = json.loads(out.read_text())["results"]
    assert "error" not in row and row["peak_mb"] is not None


def test_unknown_method():
    from torch_depth_sr.errors import UsageError

    # a library function raises a usage error (the CLI turns it into one line and exit status 2), not SystemExit
    with pytest.raises(UsageError, match="unknown speed method"):
        run_speed(types.SimpleNamespace(json=None, device="cpu", sizes="24x32", batches="1", methods=["nope"]))


# The speed work's fast paths against their references (they belong in test_singular.py /
# test_solvers.py; kept here because this session may only add this test file).


@pytest.mark.parametrize("shape", [(1, 1, 70, 65), (2, 3, 64, 100), (1, 1, 9, 130)])
def test_fft_dct_equals_matrix_dct(shape):
    from torch_depth_sr.solvers.dct import dct2, dct_matrix, idct2

    x = torch.randn(shape, dtype=torch.float64)
    ch, cw = dct_matrix(shape[-2]), dct_matrix(shape[-1])
    torch.testing.assert_close(dct2(x), ch @ x @ cw.T)
    torch.testing.assert_close(idct2(x), ch.T @ x @ cw)
    # gradcheck on one small FFT-path slice (rows of length >= 64 take the FFT path); full-size Jacobians are slow
    xr = x[:1, :1, :3, :64].detach().clone().requires_grad_()
    torch.autograd.gradcheck(lambda v: idct2(dct2(v) * 0.5), (xr,))


def test_fast_preset_row_uses_the_preset_and_reports_stages():
    row = measure("full-fast", 24, 32, 1, repeats=1)
    assert row["method"] == "full-fast" and set(row["stages"]) >= {"block_matching", "total"}


def test_tradeoffs_timing_and_accuracy_on_tiny_inputs():
    from torch_depth_sr.datasets.synthetic import make_scene
    from torch_depth_sr.evaluation.tradeoffs import accuracy, timing

    assert timing({"block_matching": {"search_window": 7, "match_layers": [2]}}, height=24, width=32, repeats=1) > 0
    s = make_scene(32, 32, seed=5)
    gt = s["gt"][None]
    noise = torch.randn(gt.shape, generator=torch.Generator().manual_seed(0))  # seeded: the test must not be flaky
    sample = {"track": "paper", "depth": gt + noise, "rgb": s["rgb"][None], "gt": gt,
              "mask": torch.ones_like(gt)}
    res = accuracy({"num_layers": 2, "block_matching": {"search_window": 7}}, [sample])
    assert set(res) == {"paper"} and 0 < res["paper"] < 1.0  # below the input noise of 1


def test_errors_by_groups_and_matches_a_direct_computation():
    from torch_depth_sr import DepthRestorer
    from torch_depth_sr.datasets.synthetic import make_scene
    from torch_depth_sr.evaluation.tune import errors_by

    s = make_scene(32, 32, seed=6)
    gt = s["gt"][None]
    mask = torch.ones_like(gt)
    mask[..., :4, :] = 0
    lr = torch.nn.functional.avg_pool2d(gt, 2)
    samples = [{"factor": 2, "depth": lr, "rgb": s["rgb"][None], "gt": gt, "mask": mask},
               {"factor": None, "depth": gt + 0.5, "rgb": s["rgb"][None], "gt": gt, "mask": mask}]
    model = DepthRestorer(num_layers=2, block_matching={"search_window": 7})
    got = errors_by(model, samples, "factor", metric="mae")
    with torch.no_grad():
        p = model(lr, s["rgb"][None], scale_factor=2)
    assert set(got) == {2, None}
    assert got[2] == [pytest.approx(float(((p - gt).abs() * mask).sum() / mask.sum()))]


def test_gpu_report_parts_run_on_any_device():
    """The GPU report's parts (run on a lent GPU, never in CI) still work; here on the CPU, tiny."""
    from torch_depth_sr.evaluation import gpu_report

    agree = gpu_report.agreement("cpu", 24, 28, 2)
    assert agree["matches_equal"] == 1.0 and agree["out_max_abs_diff"] == 0.0  # same device: same path
    assert agree["out_rmse_cpu"] < agree["input_rmse"]
    sel = gpu_report.selection_times("cpu", [(6, 8)], [1], repeats=1)
    assert all(sel[0][how + "_exact"] for how in ("topk", "split", "sort"))
    rows = gpu_report.matching_times("cpu", [(24, 28)], [1, 2], repeats=1)
    assert [r["batch"] for r in rows] == [1, 2] and all(r["seconds"] > 0 for r in rows)


def test_default_skip_covers_every_model_method_at_the_largest_batch():
    # a model method at 1088x1376 batch 8 is too slow on a 2-core CPU: the stream steps as much as full
    from torch_depth_sr.evaluation.speed import BATCHES, DEFAULT_SKIP, METHODS, MODEL_PRESETS, SIZES

    model_methods = [m for m in METHODS if m in MODEL_PRESETS or m.startswith("stream")]
    assert {"stream", "stream-fast"} <= set(model_methods)
    (h, w), b = max(SIZES), max(BATCHES)
    assert {f"{m}@{h}x{w}x{b}" for m in model_methods} <= set(DEFAULT_SKIP)
    assert all(tag.split("@")[0] in METHODS for tag in DEFAULT_SKIP)


def test_the_fronts_bench_files_replace_a_method_measured_again(tmp_path):
    """``tradeoffs --bench-json`` with several files: a later file's rows of a method replace the earlier file's
    (before, the two runs' scenes were pooled, and a retrained tier read as the mean of old and new)."""
    import json

    from torch_depth_sr.evaluation.tradeoffs import _merged_bench

    def write(name, rows):
        p = tmp_path / name
        p.write_text(json.dumps({"metadata": {"track": "paper"}, "results": rows}))
        return p

    old = write("old.json", [{"method": "fast", "scene": "Art", "rmse": 2.0}, {"method": "rgf", "scene": "Art",
                                                                               "rmse": 3.0}])
    new = write("new.json", [{"method": "fast", "scene": "Art", "rmse": 1.0}])
    rows = _merged_bench([old, new])["paper"]["results"]
    assert sorted((r["method"], r["rmse"]) for r in rows) == [("fast", 1.0), ("rgf", 3.0)]
