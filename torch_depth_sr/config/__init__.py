"""Settings of the restoration model: :class:`RestorerConfig` (version 2, nested groups), its groups, the named
configurations and the conversion of version-1 files. Field by field: ``docs/config.md``."""
from .groups import (BlockMatchingConfig, CleanSamples, EdgeRefit, EdgeSnap, FidelityBand, Guidance, GuidedPrior,
                     InitConfig, JBUConfig, LayerMultipliers, LayerWeights, OutputHold, Refiner, SidedFill,
                     SingularConfig, SolverConfig, StreamConfig, UpsamplingConfig, ValuePrior)
from .overrides import apply_overrides
from .presets import PRESETS, TIERS, TRAINED_PRESETS, preset_config
from .restorer import TERMS, RestorerConfig, from_version1, load_config_file

__all__ = [
    "BlockMatchingConfig", "CleanSamples", "EdgeRefit", "EdgeSnap", "FidelityBand", "Guidance", "GuidedPrior",
    "InitConfig", "JBUConfig", "LayerMultipliers", "LayerWeights", "OutputHold", "PRESETS", "Refiner",
    "RestorerConfig", "SidedFill", "SingularConfig", "SolverConfig", "StreamConfig", "TERMS", "TIERS",
    "TRAINED_PRESETS", "UpsamplingConfig", "ValuePrior", "apply_overrides", "from_version1", "load_config_file",
    "preset_config",
]
