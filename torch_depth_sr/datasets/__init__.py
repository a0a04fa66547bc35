"""Datasets: readers for the benchmark data, scene discovery and procedural synthetic scenes.

Every sample is a dict: ``depth`` (1,H,W) float32 (0 = missing), ``rgb`` (3,H,W) float32 in
[0,1], ``gt`` (1,H,W) float32 (0 = unknown) and ``mask`` (1,H,W) (1 = gt known) where a ground
truth exists, ``scale`` (grey levels per disparity pixel), ``name``, ``dataset``, plus extras.
"""

from torch_depth_sr.datasets.discover import TRACKS, SceneRecord, find_scenes
from torch_depth_sr.datasets.io import (
    DataFileError,
    MissingDataFileError,
    decode_sun_depth,
    read_depth,
    read_npy,
    read_pfm,
    read_pgm16,
    read_png_depth,
    read_rgb,
    write_npy,
    write_pfm,
    write_png_depth,
)
from torch_depth_sr.datasets.middlebury import MiddleburyStereo, load_middlebury_scene
from torch_depth_sr.datasets.noisy_middlebury import NoisyMiddleburyUpsampling, load_noisy_scene
from torch_depth_sr.datasets.real_sensor import RealSensorFrames, load_real_frame
from torch_depth_sr.datasets.synthetic import SyntheticScenes, make_scene

__all__ = [
    "DataFileError",
    "MiddleburyStereo",
    "MissingDataFileError",
    "NoisyMiddleburyUpsampling",
    "RealSensorFrames",
    "SceneRecord",
    "SyntheticScenes",
    "TRACKS",
    "decode_sun_depth",
    "find_scenes",
    "load_middlebury_scene",
    "load_noisy_scene",
    "load_real_frame",
    "make_scene",
    "read_depth",
    "read_npy",
    "read_pfm",
    "read_pgm16",
    "read_png_depth",
    "read_rgb",
    "write_npy",
    "write_pfm",
    "write_png_depth",
]
