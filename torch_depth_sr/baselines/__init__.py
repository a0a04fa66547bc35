"""Classical baselines: joint bilateral filter/upsampling, rolling guidance filter, sparse-coding denoising, bicubic."""
from .bicubic import BicubicUpsample, bicubic_upsample
from .dictionary import (
    DictionaryDenoise,
    OMPResult,
    batched_omp,
    dictionary_denoise,
    estimate_noise_sigma,
    overcomplete_dct_dictionary,
)
from .jbf import JointBilateralFilter, JointBilateralUpsample, jbf_denoise, joint_bilateral_filter, joint_bilateral_upsample
from .rgf import rolling_guidance_filter

__all__ = [
    "BicubicUpsample",
    "DictionaryDenoise",
    "JointBilateralFilter",
    "JointBilateralUpsample",
    "OMPResult",
    "batched_omp",
    "bicubic_upsample",
    "dictionary_denoise",
    "estimate_noise_sigma",
    "jbf_denoise",
    "joint_bilateral_filter",
    "joint_bilateral_upsample",
    "overcomplete_dct_dictionary",
    "rolling_guidance_filter",
]
