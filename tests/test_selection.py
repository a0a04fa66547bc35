"""numpy's selection returns what torch.median / torch.kthvalue / torch.unique return, bit for bit
(torch_depth_sr.selection)."""
import pytest
import torch

from torch_depth_sr.selection import distinct, kth_smallest, lower_median


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("n", [1, 2, 7, 1000, 1001])
def test_lower_median_and_kth_smallest_equal_torch(dtype, n):
    g = torch.Generator().manual_seed(n)
    v = torch.randn(n, generator=g, dtype=dtype).round(decimals=1)  # ties included
    assert torch.equal(lower_median(v), v.median())
    ks = sorted({0, n // 3, n - 1})
    assert torch.equal(kth_smallest(v, ks), torch.stack([v.kthvalue(k + 1).values for k in ks]))
    rows = torch.randn(2, 3, n, generator=g, dtype=dtype)
    assert torch.equal(lower_median(rows), rows.median(-1).values)


def test_nan_and_gradients_take_torch_path():
    v = torch.tensor([1.0, float("nan"), 3.0, 2.0])
    assert torch.isnan(lower_median(v))  # torch's answer; numpy would have sorted the NaN last
    w = torch.tensor([3.0, 1.0, 2.0], requires_grad=True)
    m = lower_median(w)
    m.backward()
    assert float(m.detach()) == 2.0 and w.grad.tolist() == [0.0, 0.0, 1.0]


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_distinct_equals_torch_unique(dtype):
    g = torch.Generator().manual_seed(5)
    for v in (torch.randn(5000, generator=g, dtype=dtype), torch.randn(5000, generator=g, dtype=dtype).round(),
              torch.zeros(0, dtype=dtype), torch.tensor([-0.0, 0.0, 2.0, 2.0], dtype=dtype)):
        out = distinct(v)
        assert out.dtype == v.dtype and torch.equal(out, torch.unique(v))
    nan = torch.tensor([1.0, float("nan"), 1.0], dtype=dtype)
    assert distinct(nan).numel() == torch.unique(nan).numel()  # torch's path (numpy would merge the NaNs)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_lower_median_of_long_rows_equals_torch(dtype):
    """Long rows take the bracketed selection: many ties (a still camera's colour changes), none, a bracket its
    strided sample misses (every other value large), a constant row, a reduction over a middle dimension."""
    g = torch.Generator().manual_seed(3)
    n = 3 * 8192 + 5
    ties = (torch.randint(-3, 4, (2, 3, n), generator=g) / 255).to(dtype)
    ties[torch.rand(ties.shape, generator=g) < 0.9] = 0
    plain = torch.randn(2, 3, n, generator=g, dtype=dtype)
    fooled = torch.empty(1, n, dtype=dtype)
    fooled[0, ::2] = 1000 + torch.arange(len(fooled[0, ::2]), dtype=dtype)
    fooled[0, 1::2] = -torch.arange(len(fooled[0, 1::2]), dtype=dtype)
    flat = torch.full((1, n), 2.5, dtype=dtype)
    for v in (ties, plain, fooled, flat):
        assert torch.equal(lower_median(v), v.median(-1).values)
    assert torch.equal(lower_median(plain.transpose(1, 2), dim=1), plain.median(-1).values)
    assert torch.equal(lower_median(plain[0, 0]), plain[0, 0].median())
