"""Can a stream setting close the `static-busy` trail (issue 28)? The shipped stream of `fast` against a few settings
that act where trail_sources.py found the deficit (the held-out first departures, the fill from the past, the
temporal prior on holes, the layers a warm frame runs), on the evaluated sequences (STREAM_SEQUENCES) and on the
tuning sequences (TUNING_SEQUENCES), as ratios to frame-by-frame restoration. A diagnosis on the evaluated sequences
(2026-12-05): nothing here was shipped, and no setting was chosen by these figures.

    python docs/measurements/issue28-stream/trail_settings.py
"""
import numpy as np
import torch

from torch_depth_sr import StreamRestorer, restore_depth
from torch_depth_sr.stream import default_stream_model
from torch_depth_sr.datasets.sequences import STREAM_SEQUENCES, TUNING_SEQUENCES, make_sequence
from torch_depth_sr.evaluation.stream import regions, synthetic_metrics

VARIANTS = {
    "shipped": {},
    "unmeasured_frames 0": {"unmeasured_frames": 0.0},
    "every layer": {"layers": None},
    "no test in time (outlier_test None)": {"outlier_test": None},
    "fill_evidence 2": {"fill_evidence": 2.0},
    "fill_evidence 4": {"fill_evidence": 4.0},
    "never from the past (fill_evidence 1000)": {"fill_evidence": 1000.0},
}


def outputs(model, seq, settings=None) -> np.ndarray:
    depth, rgb = seq["depth"][:, 0], seq["rgb"]
    stream = None if settings is None else StreamRestorer(model, settings=settings or None)
    out = []
    with torch.no_grad():
        for t in range(depth.shape[0]):
            colour = torch.from_numpy(rgb[t])[None]
            r = restore_depth(depth[t], colour, model=model) if stream is None else stream.step(depth[t], colour)
            out.append(np.asarray(r, dtype=np.float32))
    return np.stack(out)


def main() -> None:
    torch.set_num_threads(1)
    model = default_stream_model()  # the stream's model, denoise-fast (the fast tier until the 14th stop)
    for title, specs in (("evaluated", STREAM_SEQUENCES), ("tuning", TUNING_SEQUENCES)):
        seqs = [make_sequence(s, frames=30, height=120, width=160) for s in specs]
        regs = [regions(s) for s in seqs]
        frame = [synthetic_metrics(outputs(model, s), s, r) for s, r in zip(seqs, regs)]
        print(f"{title} sequences, stream / frame-by-frame (rmse, flicker, trail) per sequence:")
        print("  frame-by-frame: " + "; ".join(f"{sp.name} {m['rmse']:.2f} / {m['flicker']:.2f} / {m['trail']:.2f}"
                                               for sp, m in zip(specs, frame)))
        for name, settings in VARIANTS.items():
            cells = []
            for sp, s, r, f in zip(specs, seqs, regs, frame):
                m = synthetic_metrics(outputs(model, s, settings), s, r)
                cells.append(f"{sp.name} {m['rmse'] / f['rmse']:.3f} {m['flicker'] / f['flicker']:.3f} "
                             f"{m['trail'] / f['trail']:.4f}")
            print(f"  {name:42s} " + "; ".join(cells), flush=True)


if __name__ == "__main__":
    main()
