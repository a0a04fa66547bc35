"""Running under ``torchrun``: the process group, sharding by sequence, and the few collective steps.

``torchrun`` sets ``RANK``/``WORLD_SIZE``/``MASTER_ADDR``/``MASTER_PORT``; with ``WORLD_SIZE > 1`` a gloo process
group is started (or a gloo group made next to one the caller started), used only for small Python objects: the
plan (rank 0 reads the folders and the manifest, every rank gets the same plan), a barrier when every rank has
written its frames, and the counts. The frames themselves never travel: every rank reads its inputs and writes its
outputs on the shared file system.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from datetime import timedelta
from typing import Any

import torch.distributed as dist

__all__ = ["Group", "setup", "assign_sequences"]

# a rank with short sequences waits for the others at the final barrier: hours, not gloo's default 30 minutes.
# A rank that dies does not leave the others waiting that long: torchrun stops them all.
TIMEOUT = timedelta(days=7)


@dataclass
class Group:
    rank: int = 0
    world: int = 1
    group: Any = None  # the gloo group (None: the default group)
    started_here: bool = False

    @property
    def distributed(self) -> bool:
        return self.world > 1

    def broadcast(self, obj: Any) -> Any:
        """Rank 0's ``obj`` on every rank."""
        if not self.distributed:
            return obj
        box = [obj]
        dist.broadcast_object_list(box, src=0, group=self.group)
        return box[0]

    def gather(self, obj: Any) -> list:
        """Every rank's ``obj``, by rank, on every rank."""
        if not self.distributed:
            return [obj]
        out: list = [None] * self.world
        dist.all_gather_object(out, obj, group=self.group)
        return out

    def barrier(self) -> None:
        if self.distributed:
            dist.barrier(group=self.group)

    def close(self) -> None:
        if self.started_here and dist.is_initialized():
            dist.destroy_process_group()


def setup() -> Group:
    """The process group of this run: a single process unless ``torchrun`` (``WORLD_SIZE > 1``) or the caller
    started one."""
    if dist.is_available() and dist.is_initialized():
        group = None if dist.get_backend() == "gloo" else dist.new_group(backend="gloo", timeout=TIMEOUT)
        return Group(dist.get_rank(), dist.get_world_size(), group, False)
    world = int(os.environ.get("WORLD_SIZE", "1") or 1)
    if world <= 1:
        return Group()
    if not dist.is_available():
        from ..errors import UsageError

        raise UsageError(f"WORLD_SIZE={world} asks for {world} processes, but this torch has no torch.distributed")
    dist.init_process_group("gloo", timeout=TIMEOUT)
    return Group(dist.get_rank(), dist.get_world_size(), None, True)


def assign_sequences(frame_counts: list[int], world: int) -> list[int]:
    """The rank of each sequence: largest first to the rank with the fewest frames so far (ties: lower rank, and the
    sequences' own order). Depends only on the counts, so every rank and every rerun computes the same.

    Examples:
        >>> assign_sequences([5, 3, 3, 1], 2)
        [0, 1, 1, 0]
    """
    loads = [0] * world
    owner = [0] * len(frame_counts)
    for i in sorted(range(len(frame_counts)), key=lambda i: (-frame_counts[i], i)):
        r = min(range(world), key=lambda r: (loads[r], r))
        owner[i] = r
        loads[r] += frame_counts[i]
    return owner

