"""The command line on files: restore keeps names, dtype and units; a folder goes through a DataLoader."""
import json

import cv2
import numpy as np
import pytest
import torch

from torch_depth_sr.cli import main
from torch_depth_sr.datasets.synthetic import make_scene


def _write_pair(folder, name, seed):
    s = make_scene(40, 48, seed=seed)
    depth = (s["gt"][0].numpy() * 10).astype(np.uint16)  # "millimetres"
    depth[5:9, 5:9] = 0
    rgb = (s["rgb"].permute(1, 2, 0).numpy() * 255).astype(np.uint8)
    (folder / "depth").mkdir(exist_ok=True)
    (folder / "rgb").mkdir(exist_ok=True)
    cv2.imwrite(str(folder / "depth" / f"{name}.png"), depth)
    cv2.imwrite(str(folder / "rgb" / f"{name}.png"), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    return depth


def test_restore_file_and_folder(tmp_path):
    d0 = _write_pair(tmp_path, "a", 0)
    _write_pair(tmp_path, "b", 1)
    out = tmp_path / "out.png"
    assert main(["restore", str(tmp_path / "depth" / "a.png"), str(tmp_path / "rgb" / "a.png"), "-o", str(out),
                 "--confidence", str(tmp_path / "conf.png")]) == 0
    r = cv2.imread(str(out), cv2.IMREAD_UNCHANGED)
    assert r.dtype == np.uint16 and r.shape == d0.shape and (r > 0).all()
    assert abs(float(np.median(r)) - float(np.median(d0[d0 > 0]))) < 0.05 * float(np.median(d0[d0 > 0]))
    assert cv2.imread(str(tmp_path / "conf.png"), cv2.IMREAD_UNCHANGED).shape == d0.shape
    assert main(["restore", str(tmp_path / "depth"), str(tmp_path / "rgb"), "-o", str(tmp_path / "outdir"),
                 "--workers", "2"]) == 0
    assert sorted(p.name for p in (tmp_path / "outdir").iterdir()) == ["a.png", "b.png"]


def test_demo_writes_json_and_figure(tmp_path):
    import json

    assert main(["demo", "--out", str(tmp_path), "--json", str(tmp_path / "d.json"), "--height", "64",
                 "--width", "80"]) == 0
    d = json.loads((tmp_path / "d.json").read_text())
    assert {r["method"] for r in d["results"]} == {"input", "tv", "full"} and (tmp_path / "demo.png").exists()


def test_demo_fails_when_the_model_does_not_beat_its_ablation(tmp_path, monkeypatch, capsys):
    """The demo's quality check is an error: a "full" (default) model that returns its input makes it exit 1."""
    import torch_depth_sr.model as model_module

    real = model_module.DepthRestorer

    class Broken:
        @staticmethod
        def from_preset(name, **kw):
            return (lambda y, rgb: y.clone()) if name == "full" else real.from_preset(name, **kw)

    monkeypatch.setattr(model_module, "DepthRestorer", Broken)  # cmd_demo imports it when it runs
    assert main(["demo", "--out", str(tmp_path), "--height", "64", "--width", "80"]) == 1
    assert "expected RMSE(full) < RMSE(tv) < RMSE(input)" in capsys.readouterr().err


def test_bench_config_overrides_reach_the_model_and_bad_ones_are_refused():
    from torch_depth_sr.datasets.synthetic import make_scene
    from torch_depth_sr.evaluation.bench import _parse_config
    from torch_depth_sr.evaluation.methods import run_method

    s = make_scene(40, 40, seed=3)
    sample = {"depth": s["gt"] + 0.5 * torch.randn_like(s["gt"]), "rgb": s["rgb"]}
    small = {"num_layers": 2, "block_matching": {"search_window": 7, "k": 4}}
    a = run_method("full", sample, config=_parse_config(json.dumps(small)))
    b = run_method("full", sample, config={**small, "block_matching": {**small["block_matching"], "block_size": 5}})
    assert a.shape == (1, 1, 40, 40) and not torch.equal(a, b)
    from torch_depth_sr.errors import UsageError

    for bad in ('{"block_matching": {"block_sise": 5}}', '{"block_sise": 5}', "[1, 2]", "{not json"):
        with pytest.raises(UsageError, match="--config"):
            _parse_config(bad)


def test_network_precision_reaches_the_model_and_leaves_the_environment_as_it_was(tmp_path, monkeypatch):
    """``restore --network-precision P`` gives what the library gives inside ``network_precision(P)`` (float depth in
    and out, so no rounding hides a difference), and the two arithmetics differ; the variable it sets for worker
    processes is gone after the command."""
    import os

    from torch_depth_sr import DepthRestorer
    from torch_depth_sr.precision import ENVIRONMENT_VARIABLE, network_precision

    monkeypatch.delenv(ENVIRONMENT_VARIABLE, raising=False)
    s = make_scene(40, 48, seed=3)
    depth = (s["gt"][0].numpy() * 10).astype(np.float32)
    depth += np.random.default_rng(0).normal(0, 20, depth.shape).astype(np.float32)
    np.save(tmp_path / "d.npy", depth)
    rgb = (s["rgb"].permute(1, 2, 0).numpy() * 255).astype(np.uint8)
    cv2.imwrite(str(tmp_path / "c.png"), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    model = DepthRestorer.from_preset("best")
    rgb_t = torch.from_numpy(rgb).permute(2, 0, 1)[None].float() / 255
    runs = {}
    for p in ("float32", "bfloat16"):
        with torch.no_grad(), network_precision(p):
            runs[p] = model(torch.from_numpy(depth)[None, None], rgb_t)[0, 0].numpy()
    assert not np.array_equal(runs["float32"], runs["bfloat16"])
    for precision in ("float32", "bfloat16"):
        out = tmp_path / f"out_{precision}.npy"
        assert main(["restore", str(tmp_path / "d.npy"), str(tmp_path / "c.png"), "-o", str(out),
                     "--preset", "best", "--network-precision", precision]) == 0
        assert ENVIRONMENT_VARIABLE not in os.environ
        assert np.array_equal(np.load(out), runs[precision])
