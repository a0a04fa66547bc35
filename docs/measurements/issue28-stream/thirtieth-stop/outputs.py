"""Issue 28, thirtieth stop: the stream's outputs and confidence over 16 frames of three synthetic sequences (463×370
and 320×240), written to an .npz, to compare two trees bit for bit. From /tmp, one tree at a time:

    cd /tmp && PYTHONPATH=/path/to/tree python /path/to/outputs.py before.npz
    python /path/to/outputs.py --compare before.npz after.npz
"""
import sys

import numpy as np
import torch


def write(path: str) -> None:
    from torch_depth_sr.datasets.sequences import STREAM_SEQUENCES, TUNING_SEQUENCES, make_sequence
    from torch_depth_sr.stream import StreamRestorer, default_stream_model

    torch.set_num_threads(2)
    out = {}
    for spec, (h, w) in [(STREAM_SEQUENCES[0], (370, 463)), (STREAM_SEQUENCES[1], (240, 320)),
                         (TUNING_SEQUENCES[0], (240, 320))]:
        seq = make_sequence(spec, frames=16, height=h, width=w)
        stream = StreamRestorer(default_stream_model().eval())
        with torch.no_grad():
            for t in range(16):
                r = stream.step(seq["depth"][t].astype(np.float32), seq["rgb"][t], return_details=True)
                out[f"{spec.name}_{t}"] = np.asarray(r.depth)
                out[f"{spec.name}_{t}_confidence"] = np.asarray(r.confidence)
    np.savez(path, **out)


def compare(a_path: str, b_path: str) -> None:
    a, b = np.load(a_path), np.load(b_path)
    differ = [k for k in a.files if not np.array_equal(a[k], b[k], equal_nan=True)]
    print(f"{len(a.files)} arrays; differ: {differ}")


if __name__ == "__main__":
    compare(*sys.argv[2:4]) if sys.argv[1] == "--compare" else write(sys.argv[1])
