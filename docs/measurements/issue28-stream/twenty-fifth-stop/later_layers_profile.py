"""Where the later layers of a moving stream step go when they run on the whole frame (the device path's way, the
same values as the crops to the third digit): a cProfile of ``run_later_layers`` over steps 10-15 of one of the stream
track's evaluated sequences, the 40 largest entries by cumulative time. It tells what a design that keeps the whole
frame's tensors and runs only the per-pixel kernels (the singular test's rounds, the nonlocal terms) at the fresh
pixels would still pay: the x-update's CG and the element-wise rest.

    OMP_NUM_THREADS=2 python docs/measurements/issue28-stream/twenty-fifth-stop/later_layers_profile.py \
        --sequence static-2movers --size 480x640
"""
import argparse
import cProfile
import pstats
import time

import numpy as np
import torch

import torch_depth_sr.stream.crop_layers as crop_layers
import torch_depth_sr.stream.frame as frame
from torch_depth_sr.datasets.sequences import STREAM_SEQUENCES, make_sequence
from torch_depth_sr.stream import StreamRestorer, default_stream_model


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sequence", default="static-2movers", choices=[s.name for s in STREAM_SEQUENCES])
    p.add_argument("--size", default="480x640")
    a = p.parse_args()
    h, w = (int(t) for t in a.size.split("x"))
    seq = make_sequence(next(s for s in STREAM_SEQUENCES if s.name == a.sequence), frames=16, height=h, width=w)
    crop_layers.host_path = lambda device: False  # the later layers on the whole frame
    shipped = frame.run_later_layers
    profile, times, profiled = cProfile.Profile(), [], {"on": False}

    def later(*args):
        if not profiled["on"]:
            return shipped(*args)
        profile.enable()
        t0 = time.perf_counter()
        out = shipped(*args)
        profile.disable()
        times.append(time.perf_counter() - t0)
        return out

    frame.run_later_layers = later
    stream = StreamRestorer(default_stream_model().eval())
    with torch.no_grad():
        for t in range(16):
            profiled["on"] = t >= 10
            stream.step(seq["depth"][t].astype(np.float32), seq["rgb"][t])
    print(f"{a.sequence} {a.size}, steps 10-15, {torch.get_num_threads()} threads: the later layers on the whole "
          f"frame take {1e3 * sum(times) / len(times):.1f} ms per step (mean of {len(times)})")
    pstats.Stats(profile).sort_stats("cumulative").print_stats(40)


if __name__ == "__main__":
    main()
