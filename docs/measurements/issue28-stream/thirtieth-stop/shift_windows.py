"""Issue 28, thirtieth stop: how many of the shift test's departing windows the kernel skips (their pixels' smallest
errors over the nine positions already reach the bound) and how many it finds shifted, on frame 15 of
``static-2movers`` at 463×370.

    OMP_NUM_THREADS=2 python docs/measurements/issue28-stream/thirtieth-stop/shift_windows.py
"""
import numpy as np
import torch

import torch_depth_sr.stream.shift_kernel as kernel
from torch_depth_sr.datasets.sequences import STREAM_SEQUENCES, make_sequence
from torch_depth_sr.stream import StreamRestorer, default_stream_model
from torch_depth_sr.dilate_kernel import dilate_planes


def main() -> None:
    seq = make_sequence(STREAM_SEQUENCES[0], frames=16, height=370, width=463)
    captured = {}
    shifted_windows_cpu = kernel.shifted_windows_cpu

    def capture(*args):
        captured["args"] = args
        return shifted_windows_cpu(*args)

    kernel.shifted_windows_cpu = capture
    stream = StreamRestorer(default_stream_model().eval())
    with torch.no_grad():
        for t in range(16):
            stream.step(seq["depth"][t].astype(np.float32), seq["rgb"][t])
    y, observed, previous, noise, departs, ratio, window, clip = captured["args"]
    b, _, h, w = y.shape
    planes = [np.ascontiguousarray(t.reshape(b, h, w).numpy()) for t in (y, observed, previous, noise)]
    mask = np.ascontiguousarray(departs.reshape(b, h, w).numpy())
    near = np.empty_like(mask)
    dilate_planes(mask.view(np.uint8), window // 2, near)
    still, low = np.zeros((b, h, w)), np.zeros((b, h, w))
    kernel._errors(0, b * h, *planes, near, float(clip), still, low)
    skipped = 0
    for i, j in zip(*np.nonzero(mask[0])):
        bound = ratio * kernel._window_sum(0, i, j, planes[1], still, window // 2)
        skipped += kernel._window_sum(0, i, j, planes[1], low, window // 2) >= bound
    found = int(shifted_windows_cpu(*captured["args"]).sum())
    print(f"{STREAM_SEQUENCES[0].name} 463x370 frame 15: {int(mask.sum())} "
          f"departing windows, {skipped} skipped, {found} found shifted")


if __name__ == "__main__":
    main()
