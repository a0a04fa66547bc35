"""Classical baselines: joint bilateral filter/upsampling, sparse-coding denoising, bicubic."""
from .bicubic import BicubicUpsample, bicubic_upsample
from .jbf import JointBilateralFilter, JointBilateralUpsample, joint_bilateral_filter, joint_bilateral_upsample

__all__ = [
    "BicubicUpsample",
    "JointBilateralFilter",
    "JointBilateralUpsample",
    "bicubic_upsample",
    "joint_bilateral_filter",
    "joint_bilateral_upsample",
]
