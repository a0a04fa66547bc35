"""Issue 28, thirtieth stop: milliseconds (median of 30 calls) of the two region dilations of a later layer at 463×370:
the singular test's rounds (``singular._rounds_needed``, 2 rounds, reach 3) and the nonlocal terms' region (one pixel),
on a region shaped like a moving frame's fresh pixels. Run once per tree, from /tmp (``PYTHONPATH`` picks the tree):

    cd /tmp && PYTHONPATH=/path/to/tree GOMP_SPINCOUNT=10000 python /path/to/region_timing.py
"""
import torch
from dilate_timing import median_ms  # this folder's: the script's folder is on the path

from torch_depth_sr.singular import _rounds_needed

try:
    from torch_depth_sr.window_max import dilate

    def terms_region(region):
        return dilate(region, 1)
except ImportError:  # before this stop: terms.py dilated a float copy
    from torch_depth_sr.window_max import max_filter

    def terms_region(region):
        return max_filter(region.to(torch.float32), 3) > 0


def main() -> None:
    torch.set_num_threads(2)
    g = torch.Generator().manual_seed(0)
    region = torch.zeros(1, 1, 370, 463, dtype=torch.bool)
    region[..., 200:325, 40:185] = True  # a mover
    region[..., 140:300, 150:165] = True  # another one's edge
    region |= torch.rand(1, 1, 370, 463, generator=g) < 0.002  # scattered young runs
    print(f"singular rounds {median_ms(lambda: _rounds_needed(region, 2, 3), 30):.3f} ms, "
          f"nonlocal region {median_ms(lambda: terms_region(region), 30):.3f} ms")


if __name__ == "__main__":
    main()
