"""The trail's holes in a stream (issue 28; a diagnosis, nothing fitted): the evaluated sequence's trail pixels split
by what the stream did there (filled from the past, a hole in the previous frame too, changed or static by the
change test, held out, dropped as an outlier in time), each part's share of the trail pixels and its contribution to
the difference of the mean squared errors (stream − frame by frame, mm²), per frame; then the worst holes off the
mover in three frames, with their row of raw depth.

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/twenty-second-stop/trail_holes.py static-busy
"""
import sys, numpy as np, torch
from torch_depth_sr import StreamRestorer, restore_depth
from torch_depth_sr.stream import default_stream_model
from torch_depth_sr.stream import frame as R
from torch_depth_sr.datasets.sequences import STREAM_SEQUENCES, make_sequence
from torch_depth_sr.evaluation.stream import regions
torch.set_num_threads(1)
CAP = {}
fp = R._Frame._from_past
def from_past(self, obs):
    r = fp(self, obs); CAP["past"] = r.clone(); return r
R._Frame._from_past = from_past
jr = R.join_runs
def join_runs(*a, **k):
    r = jr(*a, **k); CAP["held_out"] = r.held_out.clone(); CAP["outlier"] = r.outlier.clone(); return r
R.join_runs = join_runs
name = sys.argv[1] if len(sys.argv) > 1 else "static-busy"  # noqa
spec = [s for s in STREAM_SEQUENCES if s.name == name][0]
model = default_stream_model()
seq = make_sequence(spec, frames=30, height=120, width=160)
reg = regions(seq)
gt, depth, rgb, moving = seq["gt"][:, 0].astype(np.float64), seq["depth"][:, 0], seq["rgb"], seq["moving"][:, 0]
frame, out, static, past, ho, outl, prevhole = [], [], [], [], [], [], []
stream = StreamRestorer(model)
with torch.no_grad():
    for t in range(depth.shape[0]):
        CAP.clear()
        colour = torch.from_numpy(rgb[t])[None]
        frame.append(np.asarray(restore_depth(depth[t], colour, model=model), dtype=np.float64))
        res = stream.step(depth[t], colour, return_details=True)
        out.append(np.asarray(res.depth, dtype=np.float64)); static.append(np.asarray(res.static) > 0)
        z = np.zeros(depth[t].shape, bool)
        past.append(CAP["past"][0, 0].numpy() if "past" in CAP else z)
        ho.append(CAP["held_out"][0, 0].numpy() if "held_out" in CAP else z)
        outl.append(CAP["outlier"][0, 0].numpy() if "outlier" in CAP else z)
        prevhole.append(depth[t - 1] == 0 if t else z)
frame, out, static, past, ho, outl, prevhole = map(np.stack, (frame, out, static, past, ho, outl, prevhole))
trail, hole = reg["trail"], depth == 0
d = (out - gt) ** 2 - (frame - gt) ** 2
n = trail.sum()
print(f"{name}: trail RMSE frame {np.sqrt(((frame - gt)[trail] ** 2).mean()):.2f}, stream {np.sqrt(((out - gt)[trail] ** 2).mean()):.2f}")
off = trail & hole & ~moving
parts = {"hole off mover": off,
         " filled from past": off & past, " not from past": off & ~past,
         "  static, hole before too": off & ~past & static & prevhole,
         "  static, new hole": off & ~past & static & ~prevhole,
         "  changed, hole before too": off & ~past & ~static & prevhole,
         "  changed, new hole": off & ~past & ~static & ~prevhole,
         "measured": trail & ~hole, " held out": trail & ho, " outlier in time": trail & outl,
         " measured, other": trail & ~hole & ~ho & ~outl,
         "hole on mover": trail & hole & moving}
for k, m in parts.items():
    print(f"  {k:32s} share {m.sum()/n:.3f}  contribution {d[m].sum()/n:+8.1f} mm²")
# per frame contribution of holes off mover
pf = [(t, d[t][off[t]].sum()/n) for t in range(30)]
print("per frame (holes off mover):", " ".join(f"{t}:{v:+.0f}" for t, v in pf if abs(v) > 5))
for t in (21, 27, 28):
    m = off[t]
    idx = np.argwhere(m)
    vals = sorted([(d[t][i, j], i, j) for i, j in idx], reverse=True)[:8]
    print(f"frame {t}: worst off-mover holes in the trail (d, i, j, gt, frame, stream, stream prev, static, prevhole)")
    for v, i, j in vals:
        print(f"   {v:9.0f} ({i:3d},{j:3d}) gt {gt[t,i,j]:7.0f} frame {frame[t,i,j]:7.0f} stream {out[t,i,j]:7.0f} prev {out[t-1,i,j]:7.0f} "
              f"static {int(static[t,i,j])} prevhole {int(prevhole[t,i,j])} row-y {depth[t,i,max(0,j-4):j+5].tolist()}")
