"""Depth video: :class:`StreamRestorer` restores a stream of RGB-D frames with state carried from frame to frame
(a temporal prior on static pixels, holes held from a confident past, the previous matches reused). Its settings are
the config group ``stream`` (:class:`~torch_depth_sr.config.StreamConfig`); the layers' term is
:class:`~torch_depth_sr.terms.TemporalPriorTerm`. Results: ``docs/stream.md``."""
from .change import ChangeTest, change_test
from .matching import StreamMatcher
from .restorer import (DEFAULT_STREAM_MODEL, StreamRestorer, StreamResult, StreamState, TemporalPrior,
                       default_stream_model, with_stream)

__all__ = ["DEFAULT_STREAM_MODEL", "ChangeTest", "StreamMatcher", "StreamRestorer", "StreamResult", "StreamState",
           "TemporalPrior", "change_test", "default_stream_model", "with_stream"]
