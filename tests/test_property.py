"""Property-based: random shapes, dtypes and 0/NaN patterns give finite output, or one of the documented refusals
(no measured pixel: InvalidDepthError; smaller than the block size: ShapeError), exactly when it applies."""
import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from torch_depth_sr import RestorerConfig, restore_depth
from torch_depth_sr.errors import InvalidDepthError, ShapeError


@st.composite
def inputs(draw):
    h = draw(st.integers(1, 24))
    w = draw(st.integers(1, 24))
    dtype = draw(st.sampled_from(["float32", "float64", "uint16", "uint8"]))
    unit = draw(st.sampled_from([1e-3, 1.0, 1000.0]))
    seed = draw(st.integers(0, 2**16))
    rng = np.random.default_rng(seed)
    depth = (rng.uniform(0.5, 3.0, (h, w)) * unit * (100 if dtype.startswith("uint") else 1))
    pattern = draw(st.sampled_from(["none", "random", "all", "rows", "nan"]))
    if pattern == "random":
        depth[rng.random((h, w)) < draw(st.floats(0, 1))] = 0
    elif pattern == "all":
        depth[:] = 0
    elif pattern == "rows":
        depth[: h // 2] = 0
    elif pattern == "nan" and dtype.startswith("float"):
        depth[rng.random((h, w)) < 0.3] = np.nan
    if dtype.startswith("uint"):
        depth = np.clip(np.nan_to_num(depth), 0, np.iinfo(dtype).max)
    depth = depth.astype(dtype)
    rgb = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
    as_torch = draw(st.booleans())
    return depth, rgb, as_torch


SMALL = dict(num_layers=2, block_matching={"search_window": 7, "k": 3})


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(inputs())
def test_no_crash_and_finite(args):
    depth, rgb, as_torch = args
    if as_torch and depth.dtype != np.uint16:
        depth = torch.from_numpy(depth)
        rgb = torch.from_numpy(rgb).permute(2, 0, 1).float() / 255
    d = np.asarray(depth, dtype=np.float64)
    block = RestorerConfig().block_matching.block_size
    if not (np.isfinite(d) & (d > 0)).any():
        with pytest.raises(InvalidDepthError, match="no measured pixel"):
            restore_depth(depth, rgb, **SMALL)
        return
    if min(d.shape) < block:
        with pytest.raises(ShapeError, match=f"at least {block}x{block}"):
            restore_depth(depth, rgb, **SMALL)
        return
    out = restore_depth(depth, rgb, **SMALL)  # any other error fails the test
    arr = out.numpy() if isinstance(out, torch.Tensor) else out
    assert arr.shape == tuple(depth.shape)
    assert np.isfinite(arr.astype(np.float64)).all()
