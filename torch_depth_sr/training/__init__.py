"""Training the unrolled restorer end to end: crop datasets, the training loop, the CLI command.

See :mod:`torch_depth_sr.training.train` (loop, DDP, checkpoints) and
:mod:`torch_depth_sr.training.datasets` (Middlebury 2006 + synthetic crops).
"""
from .datasets import CropDataset, make_datasets
from .train import TrainConfig, evaluate, load_checkpoint, masked_loss, train

__all__ = ["CropDataset", "TrainConfig", "evaluate", "load_checkpoint", "make_datasets", "masked_loss", "train"]
