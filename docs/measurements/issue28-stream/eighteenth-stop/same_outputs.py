"""Issue 28, eighteenth stop: whether a source tree's stream returns what another's did, bit for bit.

    python same_outputs.py save FILE      # with the tree before on the path (PYTHONPATH=TREE)
    python same_outputs.py compare FILE   # with the tree after

``denoise-fast`` streams (the stream's model, its shipped settings, one thread): the three synthetic stream
sequences (20 frames of 120×160) and 14 frames of the speed track's scene at 240×320 (new noise each frame). Per
frame it keeps the depth, the confidence, the evidence and the static map; ``compare`` prints how many frames are
the same bit for bit and the largest difference of the others.
"""
import sys

import torch

from torch_depth_sr.datasets.sequences import STREAM_SEQUENCES, make_sequence
from torch_depth_sr.evaluation.speed import make_inputs
from torch_depth_sr.stream import StreamRestorer, default_stream_model


def outputs() -> dict:
    torch.set_num_threads(1)
    model = default_stream_model()
    out = {}

    def keep(name, r):
        out[name] = torch.stack([torch.as_tensor(v).float() for v in (r.depth, r.confidence, r.evidence, r.static)])

    for spec in STREAM_SEQUENCES:
        seq = make_sequence(spec, frames=20, height=120, width=160)
        stream = StreamRestorer(model)
        for t in range(20):
            keep(f"{spec.name}/{t}", stream.step(torch.from_numpy(seq["depth"][t, 0]), torch.from_numpy(seq["rgb"][t]),
                                                 return_details=True))
    y, rgb, gt = make_inputs(240, 320, 1)
    g = torch.Generator().manual_seed(1)
    stream = StreamRestorer(model)
    for t in range(14):
        frame = torch.where(y > 0, (gt + 5 * torch.randn(y.shape, generator=g)).clamp_min(1.0), torch.zeros_like(y))
        keep(f"speed/{t}", stream.step(frame, rgb, return_details=True))
    return out


def main() -> None:
    mode, path = sys.argv[1], sys.argv[2]
    now = outputs()
    if mode == "save":
        torch.save(now, path)
        return
    before = torch.load(path, weights_only=True)
    differ = {k: float((before[k] - v).abs().max()) for k, v in now.items() if not torch.equal(before[k], v)}
    print(f"{len(now) - len(differ)} of {len(now)} frames the same bit for bit; differing: {differ}")


if __name__ == "__main__":
    main()
