"""Where the stream's trail error exceeds frame-by-frame restoration's (issue 28; diagnosis only, nothing is fitted
here): the evaluation sequences' trail pixels (``evaluation.stream.regions``), split by what the pixel is, with each
part's share of the trail pixels and its contribution to the difference of the mean squared errors (stream − frame,
mm²; the trail RMSEs are the square roots of the two means).

    python docs/measurements/issue28-stream/trail_sources.py [SEQUENCE ...]   (default static-busy static-2movers)
"""
import sys

import numpy as np
import torch

from torch_depth_sr import StreamRestorer, restore_depth
from torch_depth_sr.stream import default_stream_model
from torch_depth_sr.datasets.sequences import STREAM_SEQUENCES, make_sequence
from torch_depth_sr.evaluation.stream import regions
from torch_depth_sr.window_max import dilate

torch.set_num_threads(1)
names = sys.argv[1:] or ["static-busy", "static-2movers"]
model = default_stream_model()  # the stream's model, denoise-fast (the fast tier until the 14th stop)
for spec in STREAM_SEQUENCES:
    if spec.name not in names:
        continue
    seq = make_sequence(spec, frames=30, height=120, width=160)
    reg = regions(seq)
    gt, depth, rgb, moving = seq["gt"][:, 0].astype(np.float64), seq["depth"][:, 0], seq["rgb"], seq["moving"][:, 0]
    frame, stream_out, static = [], [], []
    stream = StreamRestorer(model)
    with torch.no_grad():
        for t in range(depth.shape[0]):
            colour = torch.from_numpy(rgb[t])[None]
            frame.append(np.asarray(restore_depth(depth[t], colour, model=model), dtype=np.float64))
            res = stream.step(depth[t], colour, return_details=True)
            stream_out.append(np.asarray(res.depth, dtype=np.float64))
            static.append(np.asarray(res.static) > 0)
    frame, stream_out, static = np.stack(frame), np.stack(stream_out), np.stack(static)
    trail, near, hole = reg["trail"], dilate(torch.from_numpy(moving.astype(bool))[:, None], 2)[:, 0].numpy(), depth == 0
    d = (stream_out - gt) ** 2 - (frame - gt) ** 2
    n = trail.sum()
    print(f"{spec.name}: trail RMSE frame {np.sqrt(((frame - gt)[trail] ** 2).mean()):.2f}, "
          f"stream {np.sqrt(((stream_out - gt)[trail] ** 2).mean()):.2f}; mean squared error difference "
          f"{d[trail].sum() / n:+.1f} mm²")
    parts = {
        "measured": trail & ~hole, "hole": trail & hole, "hole, off the mover": trail & hole & ~moving,
        "on the mover": trail & moving, "off the mover": trail & ~moving,
        "static (change test), within 2 px of a mover": trail & static & near,
        "changed (change test), within 2 px of a mover": trail & ~static & near,
        "static, where a mover was (not within 2 px now)": trail & static & ~near,
        "changed, where a mover was (not within 2 px now)": trail & ~static & ~near,
    }
    for k, m in parts.items():
        print(f"  {k:50s} share {m.sum() / n:.3f}  contribution {d[m].sum() / n:+8.1f} mm²")
