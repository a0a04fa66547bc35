"""Whole recordings: every frame of every RGB-D sequence under a folder, restored in order, with a manifest.

* :func:`discover_recordings` finds the sequences (TUM ``associations.txt`` or ``depth.txt`` + ``rgb.txt``, an
  ``index.txt`` listing, a ``depth/`` + ``rgb/`` folder; a folder of recordings gives several);
* :func:`restore_dataset` restores them: each sequence frame by frame through one restorer (its state carried),
  sequences in parallel (``workers=N`` processes, and across ``torchrun`` ranks), outputs written atomically,
  ``manifest.jsonl`` records each frame, an interrupted run resumes (``resume=True``).

``torch-depth-sr restore --recordings ROOT OUT`` is the command line; ``docs/recordings.md`` the user guide.
"""
from .layouts import Frame, Sequence, associate_timestamps, discover_recordings
from .manifest import read_manifest
from .restore import RestoreSummary, restore_dataset
from .restorers import FrameByFrame, PretrainedRestorer, Streaming

__all__ = ["Frame", "FrameByFrame", "PretrainedRestorer", "RestoreSummary", "Sequence", "Streaming",
           "associate_timestamps", "discover_recordings", "read_manifest", "restore_dataset"]
