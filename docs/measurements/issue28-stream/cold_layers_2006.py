"""Issue 28: what the first layer alone of the ``fast`` tier gives on a frame with no past, on the FITTING split (the
eleven Middlebury 2006 scenes, ``fit.py``'s protocol of ``bench --track paper|sensor``). A stream frame whose scene
changed has no temporal prior and no running mean, so with ``StreamConfig.layers = 1`` its changed pixels get this.

    OMP_NUM_THREADS=1 python docs/measurements/issue28-stream/cold_layers_2006.py

Prints the mean RMSE / MAE per track of the tier (3 layers) and of its first layer alone (then the refiner).
"""
import copy
import sys
from pathlib import Path

import torch
from torch import nn

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "issue27-tiers"))
from fit import accuracy  # noqa: E402

from torch_depth_sr.stream import default_stream_model

torch.set_num_threads(1)
full = default_stream_model()  # the stream's model, denoise-fast (the fast tier until the 14th stop)
first = copy.copy(full)
first._modules = dict(full._modules)
first.layers = nn.ModuleList([full.layers[0]])
for name, model in (("3 layers", full), ("1 layer", first)):
    a = accuracy(model)
    print(name, {t: (round(v["rmse"], 4), round(v["mae"], 4)) for t, v in a.items()}, flush=True)
