"""Where the near-clean harm of Baby1 and Baby3 comes from: the restored pixels more than 3 grey levels from the truth
on the σ 0.3 crops of near_clean_2006.py, whether the model trusted their measurements, and the 7×7 neighbourhood of
the worst one (truth, restored, trusted).

    python docs/measurements/issue27-tiers/twelfth-stop/near_clean_strip.py [TIER]
"""
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "default-tier"))
from near_clean_2006 import near_clean_crop, rmse  # noqa: E402

from torch_depth_sr import DepthRestorer  # noqa: E402

torch.set_num_threads(2)
tier = sys.argv[1] if len(sys.argv) > 1 else "default"
model = DepthRestorer.from_preset(tier)
np.set_printoptions(linewidth=200, precision=1, suppress=True)
for scene in ("Baby1", "Baby3"):
    depth, rgb, measured, noisy = near_clean_crop(scene, 0.3)
    r = model.restore_with_details(torch.from_numpy(noisy)[None, None],
                                   torch.from_numpy(rgb).permute(2, 0, 1)[None].float() / 255)
    out, trusted = r.depth[0, 0].numpy(), r.trusted[0, 0].numpy()
    err = np.where(measured, np.abs(out - depth), 0)
    big = err > 3
    print(f"{tier} {scene}: RMSE {rmse(out, depth, measured):.3f} (input {rmse(noisy, depth, measured):.3f}); "
          f"{int(big.sum())} pixels > 3 levels off, {int((trusted[big] == 0).sum())} of them distrusted; "
          f"worst {err.max():.1f}")
    i, j = np.unravel_index(err.argmax(), err.shape)
    window = np.s_[i - 3:i + 4, j - 3:j + 4]
    print(f"  around ({i}, {j}): truth (0 = unmeasured)\n{depth[window].astype(float)}\n  restored\n{out[window]}\n"
          f"  trusted\n{trusted[window]}")
