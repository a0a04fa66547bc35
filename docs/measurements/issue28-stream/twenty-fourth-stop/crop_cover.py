"""Issue 28, twenty-fourth stop: would a tighter set of crops make the later layers of a stream step cheaper?

The later layers run on rectangles around the fresh pixels (:func:`~torch_depth_sr.stream.matching.crops`: bands of
rows, then runs of columns, merged where their padding would overlap). On ``static-2movers`` at 480×640 a few specks of
restarted runs far from the movers stretch them into one box over 60–80 % of the frame around 10 % fresh pixels. Here a
cost-aware cover (each connected group of fresh pixels its own box; two boxes merged while the padded union's area is
below the two areas plus ``fixed`` pixels, or while their cores overlap) is timed against it, on the state and
observation of one step (step 15), the later layers alone, five runs each, median; and the whole frame. Then the
sequence's mean RMSE over steps 6–15 of the stream with each cover (a crop's CG has its own step sizes, so another
cover gives other values).

    OMP_NUM_THREADS=2 python docs/measurements/issue28-stream/twenty-fourth-stop/crop_cover.py

Wall-clock time on this machine: run it alone.
"""
from __future__ import annotations

import time

import cv2
import numpy as np
import torch

import torch_depth_sr.stream.crop_layers as crop_layers
import torch_depth_sr.stream.frame as frame
from torch_depth_sr.datasets.sequences import STREAM_SEQUENCES, make_sequence
from torch_depth_sr.stream import StreamRestorer, default_stream_model

GROUP = 4  # px: pixels this close are one group before merging (bounds the number of boxes on specks)


def cover(mask: torch.Tensor, pad: int, fixed: float) -> list:
    """Boxes ``(rows, cols, core_rows, core_cols)`` as ``crops`` returns them, chosen for cost (module docstring)."""
    h, w = mask.shape[-2:]
    m = mask.flatten(0, 1).any(0).to(torch.uint8).numpy()
    grouped = cv2.dilate(m, np.ones((2 * GROUP + 1, 2 * GROUP + 1), np.uint8))
    _, _, st, _ = cv2.connectedComponentsWithStats(grouped, connectivity=8)
    x0, y0, x1, y1 = st[1:, 0], st[1:, 1], st[1:, 0] + st[1:, 2], st[1:, 1] + st[1:, 3]
    boxes = np.stack([np.where(y0 > 0, y0 + GROUP, 0), np.where(y1 < h, y1 - GROUP, h),
                      np.where(x0 > 0, x0 + GROUP, 0), np.where(x1 < w, x1 - GROUP, w)], 1).astype(np.int64)

    def area(b):
        return ((np.minimum(b[..., 1] + pad, h) - np.maximum(b[..., 0] - pad, 0))
                * (np.minimum(b[..., 3] + pad, w) - np.maximum(b[..., 2] - pad, 0)))

    while len(boxes) > 1:
        a, b = boxes[:, None], boxes[None, :]
        union = np.stack([np.minimum(a[..., 0], b[..., 0]), np.maximum(a[..., 1], b[..., 1]),
                          np.minimum(a[..., 2], b[..., 2]), np.maximum(a[..., 3], b[..., 3])], -1)
        own = area(boxes) + fixed
        saving = (own[:, None] + own[None, :] - area(union) - fixed).astype(np.float64)
        overlap = ((np.minimum(a[..., 1], b[..., 1]) > np.maximum(a[..., 0], b[..., 0]))
                   & (np.minimum(a[..., 3], b[..., 3]) > np.maximum(a[..., 2], b[..., 2])))
        saving = np.where(overlap, np.inf, saving)
        np.fill_diagonal(saving, -np.inf)
        i, j = np.unravel_index(int(np.argmax(saving)), saving.shape)
        if saving[i, j] <= 0:
            break
        boxes[i] = union[i, j]
        boxes = np.delete(boxes, j, 0)
    return [(slice(max(0, r0 - pad), min(h, r1 + pad)), slice(max(0, c0 - pad), min(w, c1 + pad)),
             slice(r0, r1), slice(c0, c1)) for r0, r1, c0, c1 in boxes.tolist()]


def main() -> None:
    torch.set_num_threads(2)
    spec = next(s for s in STREAM_SEQUENCES if s.name == "static-2movers")
    seq = make_sequence(spec, frames=16, height=480, width=640)
    stream = StreamRestorer(default_stream_model().eval())
    shipped_later, shipped_crops = frame.run_later_layers, crop_layers.crops
    caught = {}

    def catch(layers, state, obs, fresh):
        caught["args"] = (layers, state, obs, fresh)
        return shipped_later(layers, state, obs, fresh)

    frame.run_later_layers = catch
    with torch.no_grad():
        for t in range(16):
            stream.step(seq["depth"][t].astype(np.float32), seq["rgb"][t])
        layers, state, obs, fresh = caught["args"]
        pad = crop_layers.padding(obs, len(layers))
        share = float(fresh.float().mean())
        print(f"static-2movers 480x640, step 15: fresh {share:.3f} of the frame, padding {pad} px")
        print(f"{'cover':34s} {'boxes':>5s} {'area':>6s} {'later layers':>13s}")
        covers = [("crops (shipped)", None)] + [(f"cost-aware, fixed {f} px", f) for f in (0, 6000, 12000, 40000)]
        for label, fixed in covers:
            crop_layers.crops = shipped_crops if fixed is None else (lambda m, p, f=fixed: cover(m, p, f))
            boxes = crop_layers.crops(fresh, pad)
            share = sum((r.stop - r.start) * (c.stop - c.start) for r, c, _, _ in boxes) / fresh[0, 0].numel()
            times = []
            for _ in range(5):
                t0 = time.perf_counter()
                crop_layers.run_later_layers(layers, state, obs, fresh)
                times.append(time.perf_counter() - t0)
            print(f"{label:34s} {len(boxes):5d} {share:6.2f} {np.median(times) * 1e3:10.1f} ms")
        crop_layers.crops = shipped_crops
        times = []
        for _ in range(5):
            t0 = time.perf_counter()
            crop_layers.run_later_layers(layers, state, obs, torch.ones_like(fresh))
            times.append(time.perf_counter() - t0)
        print(f"{'whole frame':34s} {1:5d} {1.0:6.2f} {np.median(times) * 1e3:10.1f} ms")
    frame.run_later_layers = shipped_later
    gt = seq["gt"][:, 0].astype(np.float64)
    for label, fixed in [("crops (shipped)", None), ("cost-aware, fixed 6000 px", 6000),
                         ("cost-aware, fixed 12000 px", 12000)]:
        crop_layers.crops = shipped_crops if fixed is None else (lambda m, p, f=fixed: cover(m, p, f))
        stream = StreamRestorer(default_stream_model().eval())
        with torch.no_grad():
            out = [stream.step(seq["depth"][t].astype(np.float32), seq["rgb"][t]) for t in range(16)]
        rmse = np.mean([np.sqrt(np.mean((out[t][0] - gt[t]) ** 2)) for t in range(6, 16)])
        print(f"{label:34s} mean RMSE of steps 6-15: {rmse:.3f}")
    crop_layers.crops = shipped_crops


if __name__ == "__main__":
    main()
