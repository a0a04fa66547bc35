"""The benchmark tracks' degradations live in :mod:`torch_depth_sr.degradations` (one home, used by the benchmark,
training, the transforms and the examples); this module keeps the old import path working."""
from ..degradations import *  # noqa: F401,F403
from ..degradations import __all__  # noqa: F401
from ..degradations import _DISC2, _blobs, _choose, _gt_numpy, _pack, _to_tensor  # noqa: F401
