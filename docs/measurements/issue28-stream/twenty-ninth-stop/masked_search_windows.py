"""Issue 28, twenty-ninth stop: the band height and the joining gap of the masked exact search
(``block_matching.cpu_exact._windows``) on a moving stream's own fresh pixels, and what the crops it replaced covered.

    OMP_NUM_THREADS=2 python docs/measurements/issue28-stream/twenty-ninth-stop/masked_search_windows.py

``static-2movers`` at 480×640 (20 frames): the fresh masks and x⁰ of its last six frames, each searched three times
per setting; medians in ms.
"""
import time

import numpy as np
import torch

import torch_depth_sr.block_matching.cpu_exact as C
import torch_depth_sr.stream.matching as M
from torch_depth_sr.block_matching import block_match_at
from torch_depth_sr.datasets.sequences import STREAM_SEQUENCES, make_sequence
from torch_depth_sr.stream import StreamRestorer, default_stream_model


def main() -> None:
    frames = []
    search_fresh = M.StreamMatcher._search_fresh

    def capture(self, x, obs, q, dist, index):
        frames.append((x.clone(), obs.rgb.clone(), q.clone(), self.fresh.clone(), dist.clone(), index.clone()))
        return search_fresh(self, x, obs, q, dist, index)

    M.StreamMatcher._search_fresh = capture
    seq = make_sequence(STREAM_SEQUENCES[0], frames=20, height=480, width=640)
    stream = StreamRestorer(default_stream_model().eval())
    with torch.no_grad():
        for t in range(20):
            stream.step(seq["depth"][t].astype(np.float32), seq["rgb"][t])
    frames = frames[-6:]
    fresh = [f[3] for f in frames]
    area = np.mean([sum((r.stop - r.start) * (c.stop - c.start) for r, c, _, _ in M.crops(f, 4)) / f[0, 0].numel()
                    for f in fresh])
    print(f"static-2movers 480x640, frames 14-19: fresh {np.mean([float(f.float().mean()) for f in fresh]):.3f} of "
          f"the frame; the crops of the search radius + block radius covered {area:.3f}")
    print("rows  gap  ms (median)  bands  window area")
    for rows in (8, 16, 32):
        for gap in (8, 32, 64):
            C._WINDOW_ROWS, C._WINDOW_GAP = rows, gap
            times = []
            for _ in range(3):
                for x, rgb, q, where, dist, index in frames:
                    dist, index = dist.clone(), index.clone()
                    t0 = time.perf_counter()
                    block_match_at(x, rgb, q, where, dist, index, block_size=3, search_window=7, color_weight=400.0)
                    times.append(time.perf_counter() - t0)
            bands = [C._windows(w[:, 0].numpy(), rows, 3) for w in fresh]
            cover = np.mean([sum((h1 - h0) * (wb - wa) for _, h0, h1, wa, wb in b) / (480 * 640) for b in bands])
            print(f"{rows:4d} {gap:4d}  {1e3 * np.median(times):10.2f}  {np.mean([len(b) for b in bands]):5.1f}  "
                  f"{cover:.3f}")


if __name__ == "__main__":
    main()
