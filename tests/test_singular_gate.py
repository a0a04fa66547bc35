"""The singular test's per-sample gate (stages._gate): the share of gross failures over the frame, and, with
``obs.gate_region`` (a stream's pixels measured in this frame alone), within that region too."""
import math
from types import SimpleNamespace

import torch

from torch_depth_sr.config import SingularConfig
from torch_depth_sr.stages import _gate

GATE = SingularConfig().gate  # 0.002


def _case(h: int, w: int, failures: list, region=None):
    observed = torch.ones(1, 1, h, w)
    conf = torch.ones(1, 1, h, w)
    for y, x in failures:
        conf[0, 0, y, x] = math.exp(-3.0)  # a gross failure: P below e⁻²
    q = (conf > math.exp(-2.0)).float()
    obs = SimpleNamespace(observed=observed, gate_region=region)
    return _gate(obs, q, conf, SingularConfig())


def test_a_frame_share_below_the_gate_is_clean_and_trusts_every_measurement():
    q, clean = _case(100, 100, [(5, 5), (50, 50)])  # 2 of 10 000: 0.0002
    assert bool(clean.all()) and bool((q == 1).all())
    q, clean = _case(100, 100, [(i, i) for i in range(30)])  # 0.003
    assert not bool(clean.any()) and float(q.sum()) == 10_000 - 30


def test_a_region_with_its_own_share_above_the_gate_is_not_clean():
    """Three flying pixels beside a mover, among 1000 pixels measured afresh, in a frame whose other 99 000 are runs'
    means: 3/100 000 of the frame is below the gate, 3/1000 of the region is not."""
    region = torch.zeros(1, 1, 200, 500, dtype=torch.bool)
    region[..., :10, :100] = True  # 1000 pixels
    failures = [(1, 1), (5, 50), (9, 99)]
    assert bool(_case(200, 500, failures)[1].all())  # the frame alone: clean
    q, clean = _case(200, 500, failures, region)
    assert not bool(clean.any()) and float(q[region.expand_as(q)].sum()) == 1000 - 3


def test_a_region_of_fewer_than_one_over_gate_pixels_is_not_read():
    region = torch.zeros(1, 1, 200, 500, dtype=torch.bool)
    region[..., :4, :100] = True  # 400 < 1/0.002 = 500 pixels: one failure there cannot be told from noise
    q, clean = _case(200, 500, [(1, 1)], region)
    assert bool(clean.all())
    region[..., :6, :100] = True  # 600 pixels: 1/600 is below the gate
    assert bool(_case(200, 500, [(1, 1)], region)[1].all())
    assert not bool(_case(200, 500, [(1, 1), (2, 2)], region)[1].any())  # 2/600 is not


def test_the_gate_is_per_sample():
    region = torch.zeros(2, 1, 100, 100, dtype=torch.bool)
    region[:, :, :30] = True  # 3000 pixels in each sample
    observed, conf = torch.ones(2, 1, 100, 100), torch.ones(2, 1, 100, 100)
    conf[1, 0, 0, :10] = math.exp(-3.0)  # 10/3000 in the second sample's region; 10/10 000 of its frame
    _, clean = _gate(SimpleNamespace(observed=observed, gate_region=region), (conf > 0.2).float(), conf,
                     SingularConfig())
    assert clean.flatten().tolist() == [True, False]
