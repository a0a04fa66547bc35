"""The RealSense SDK's temporal filter (``rs2::temporal_filter``, librealsense) as a baseline for depth streams.

It runs the SDK's own filter through ``pyrealsense2`` (an optional extra: ``pip install torch_depth_sr[bench-stream]``
or ``pip install pyrealsense2``; on Linux the wheel also needs the system's ``libusb-1.0``). Frames built from numpy
arrays reach it through a ``software_device``: a virtual Z16 depth sensor whose frames are the arrays themselves, so
no camera is needed. The filter keeps, per pixel, an exponential moving average (``alpha``: the weight of the new
value) that restarts where the new value differs from the average by more than ``delta`` (depth units), and its
*persistence* (``holes_fill``, 0–8) fills a missing pixel with the last valid value when the pixel was valid often
enough in the last frames (0 off, 1 valid in 8/8, 2 in 2/last 3, 3 in 2/last 4, 4 in 2/8, 5 in 1/last 2, 6 in
1/last 5, 7 in 1/last 8, 8 always).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import DepthSRError

__all__ = ["RealSenseTemporal", "INSTALL_HINT", "realsense_available"]

INSTALL_HINT = ("the RealSense temporal filter needs pyrealsense2: pip install 'torch_depth_sr[bench-stream]' "
                "(or pip install pyrealsense2; on Linux also the system's libusb-1.0, e.g. apt-get install "
                "libusb-1.0-0)")


def _rs() -> Any:
    try:
        import pyrealsense2 as rs
    except ImportError as exc:  # the wheel missing, or libusb missing under it
        raise DepthSRError(f"{INSTALL_HINT} ({exc}).") from exc
    return rs


def realsense_available() -> bool:
    """Whether pyrealsense2 imports."""
    try:
        _rs()
    except DepthSRError:
        return False
    return True


class RealSenseTemporal:
    """``rs2::temporal_filter`` over a stream of ``(H, W)`` uint16 depth maps (0 = no measurement).

    Args:
        alpha: weight of the new frame in the moving average, in [0, 1] (SDK default 0.4).
        delta: a step larger than this (depth units) restarts the average (SDK default 20).
        persistence: the SDK's ``holes_fill`` option, 0–8 (SDK default 3, "valid in 2 of the last 4").

    :meth:`step` returns the filtered frame (uint16, holes that persistence did not fill stay 0); :meth:`reset`
    starts a new stream (a new filter).
    """

    stateful = True

    def __init__(self, alpha: float = 0.4, delta: float = 20.0, persistence: int = 3):
        self.alpha, self.delta, self.persistence = float(alpha), float(delta), int(persistence)
        self._rs = _rs()
        self._shape = None
        self._frame = 0

    def reset(self) -> None:
        self._shape = None

    def _start(self, h: int, w: int) -> None:
        rs = self._rs
        self._device = rs.software_device()
        sensor = self._device.add_sensor("Depth")
        intr = rs.intrinsics()
        intr.width, intr.height, intr.fx, intr.fy, intr.ppx, intr.ppy = w, h, float(w), float(w), w / 2, h / 2
        intr.model = rs.distortion.none
        vs = rs.video_stream()
        vs.type, vs.width, vs.height, vs.fps, vs.bpp, vs.fmt = rs.stream.depth, w, h, 30, 2, rs.format.z16
        vs.intrinsics, vs.index, vs.uid = intr, 0, 1
        self._profile = sensor.add_video_stream(vs)
        sensor.add_read_only_option(rs.option.depth_units, 0.001)
        self._queue = rs.frame_queue(4, keep_frames=True)
        sensor.open(self._profile)
        sensor.start(self._queue)
        self._sensor = sensor
        self._filter = rs.temporal_filter(self.alpha, self.delta, self.persistence)
        self._shape, self._frame = (h, w), 0

    def step(self, depth: np.ndarray) -> np.ndarray:
        d = np.ascontiguousarray(depth, dtype=np.uint16)
        if d.ndim != 2:
            raise DepthSRError(f"RealSenseTemporal takes (H, W) uint16 frames; got shape {d.shape}.")
        if self._shape != d.shape:
            self._start(*d.shape)
        rs = self._rs
        f = rs.software_video_frame()
        f.pixels, f.stride, f.bpp = d, d.shape[1] * 2, 2
        f.timestamp, f.domain, f.frame_number = self._frame * 33.3, rs.timestamp_domain.hardware_clock, self._frame
        f.profile = self._profile.as_video_stream_profile()
        self._sensor.on_video_frame(f)
        frame = self._queue.wait_for_frame(5000)
        self._frame += 1
        return np.array(np.asanyarray(self._filter.process(frame).get_data()), dtype=np.uint16, copy=True)

    def __repr__(self) -> str:
        return f"RealSenseTemporal(alpha={self.alpha:g}, delta={self.delta:g}, persistence={self.persistence})"
