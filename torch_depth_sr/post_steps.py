"""The steps after the layers, one module per step, each owning its settings; the model runs those of the task
in order (``DepthRestorer.post[task]``) and a step that is off is absent.

Denoising: edge snapping and the refit to the measurements (samples the singular gate found outliers in), the edge
refiner trained for denoising, the fidelity band. Guided upsampling: the hold to x⁰, the edge refiner trained for
upsampling. Every step takes ``(x, state, obs, initial)``: the estimate in units of the scale, the layers' last
:class:`~torch_depth_sr.state.RestorationState`, the :class:`~torch_depth_sr.observation.Observation` and the
:class:`~torch_depth_sr.initial.InitialEstimate`.
"""
from __future__ import annotations

import torch
from torch import nn

from .config import EdgeRefit, EdgeSnap, FidelityBand, OutputHold, RestorerConfig, UpsamplingConfig
from .edge_snap import refit_to_measurements, snap_to_sides
from .fidelity import clamp_to_measurements, noise_band
from .initial import InitialEstimate
from .observation import Observation
from .refiner import EdgeRefiner
from .state import RestorationState, stage
from .upsampling import hold_to_initial, upsampling_reference

__all__ = ["DenoiseRefineStep", "EdgeRefitStep", "EdgeSnapStep", "FidelityBandStep", "OutputHoldStep", "RefineStep",
           "UpsampleRefineStep", "post_steps", "run_steps"]


def _edge_active(state: RestorationState) -> torch.Tensor:
    """Where the edge steps act: the samples the singular gate found outliers in (``~state.clean``), less the pixels
    a stream holds (``state.held``)."""
    return ~state.clean if state.held is None else ~state.clean & ~state.held


class EdgeSnapStep(nn.Module):
    """Flying pixels and edge blends go to their side (:func:`~torch_depth_sr.edge_snap.snap_to_sides`), on the
    samples the singular gate found outliers in (nothing without a guide). Built only where a gated singular test
    gives that verdict."""

    def __init__(self, settings: EdgeSnap):
        super().__init__()
        self.settings = settings

    def forward(self, x: torch.Tensor, state: RestorationState, obs: Observation,
                initial: InitialEstimate) -> torch.Tensor:
        if obs.rgb is None:
            return x
        c = self.settings
        with stage(obs.log.timings, "snap", x.device):
            return snap_to_sides(x, obs.rgb, rounds=c.rounds, radius=c.radius, share=c.share,
                                 sigma_color=c.sigma_color, sigma_space=c.sigma_space, active=_edge_active(state),
                                 edge=c.edge)

    def extra_repr(self) -> str:
        return ", ".join(f"{k}={v}" for k, v in self.settings.to_dict().items())


class EdgeRefitStep(nn.Module):
    """Values near depth edges refitted to their side's measurements
    (:func:`~torch_depth_sr.edge_snap.refit_to_measurements`), on the samples the singular gate found outliers in.
    Built only where a gated singular test gives that verdict."""

    def __init__(self, settings: EdgeRefit):
        super().__init__()
        self.settings = settings

    def forward(self, x: torch.Tensor, state: RestorationState, obs: Observation,
                initial: InitialEstimate) -> torch.Tensor:
        if obs.rgb is None:
            return x
        c = self.settings
        with stage(obs.log.timings, "snap", x.device):
            return refit_to_measurements(x, obs.y, obs.observed, obs.rgb, radius=c.radius, band=c.band, edge=c.edge,
                                         sigma_color=c.sigma_color, active=_edge_active(state))

    def extra_repr(self) -> str:
        return ", ".join(f"{k}={v}" for k, v in self.settings.to_dict().items())


class RefineStep(nn.Module):
    """The learned edge correction (:class:`~torch_depth_sr.refiner.EdgeRefiner`), bounded by the 3×3 range of
    what was measured around each pixel (:meth:`bound`). The network is the model's ``refiner`` (its parameters keep
    that key); the step only holds it."""

    def __init__(self, refiner: EdgeRefiner):
        super().__init__()
        self.network = (refiner,)  # held, not registered: the parameters stay at ``refiner.*``

    def bound(self, x: torch.Tensor, state: RestorationState, obs: Observation) -> torch.Tensor:
        raise NotImplementedError

    def noise(self, x: torch.Tensor, obs: Observation) -> torch.Tensor:
        raise NotImplementedError

    def forward(self, x: torch.Tensor, state: RestorationState, obs: Observation,
                initial: InitialEstimate) -> torch.Tensor:
        if obs.rgb is None:
            return x
        with stage(obs.log.timings, "refine", x.device):
            return self.network[0](x, self.bound(x, state, obs), obs.rgb, self.noise(x, obs))


class DenoiseRefineStep(RefineStep):
    """Bounded by the trusted measurements (the model's value elsewhere); reads the model's noise level."""

    def bound(self, x: torch.Tensor, state: RestorationState, obs: Observation) -> torch.Tensor:
        return torch.where(state.q * obs.observed > 0, obs.y, x)

    def noise(self, x: torch.Tensor, obs: Observation) -> torch.Tensor:
        return obs.sigma.to(x) / obs.scale


class UpsampleRefineStep(RefineStep):
    """Bounded by the input (at its holes the model's value degraded by K); reads the white noise level."""

    def bound(self, x: torch.Tensor, state: RestorationState, obs: Observation) -> torch.Tensor:
        return torch.where(obs.observed > 0, obs.y, obs.K(x))

    def noise(self, x: torch.Tensor, obs: Observation) -> torch.Tensor:
        return obs.white.to(x) / obs.scale


class FidelityBandStep(nn.Module):
    """Trusted measurements bound x on their own grid (:func:`~torch_depth_sr.fidelity.clamp_to_measurements`)."""

    bounds_output = True  # a do-no-harm bound: it acts on the output as returned, held pixels included

    def __init__(self, settings: FidelityBand):
        super().__init__()
        self.settings = settings

    def forward(self, x: torch.Tensor, state: RestorationState, obs: Observation,
                initial: InitialEstimate) -> torch.Tensor:
        band = noise_band(obs.grid_step, obs.noise, self.settings.width)  # in units of the scale
        return clamp_to_measurements(x, obs.y, state.q * obs.observed, band)

    def extra_repr(self) -> str:
        return f"width={self.settings.width:g}"


class OutputHoldStep(nn.Module):
    """Do no harm on upsampling: the output held to x⁰ rebuilt with the white noise level
    (:func:`~torch_depth_sr.upsampling.hold_to_initial`)."""

    bounds_output = True  # a do-no-harm bound, as FidelityBandStep

    def __init__(self, settings: OutputHold, upsampling: UpsamplingConfig):
        super().__init__()
        self.settings, self.upsampling = settings, upsampling

    def forward(self, x: torch.Tensor, state: RestorationState, obs: Observation,
                initial: InitialEstimate) -> torch.Tensor:
        ref = initial.reference  # x⁰'s filters, computed once per forward
        # when the input's gradient is wanted, the filters run again, each its own node, so that the backward
        # through them runs as before (once per use; one summed backward moves the input's gradient by ~1e-7)
        separate = ref.lowres.requires_grad
        if separate:
            ref = upsampling_reference(ref.lowres, obs.observed, obs.rgb, obs.K.scale, self.upsampling)
        return hold_to_initial(x, ref, obs.K, self.upsampling, self.settings, obs.noise,
                               obs.white.to(obs.sigma) / obs.scale, separate_evidence=separate)

    def extra_repr(self) -> str:
        return ", ".join(f"{k}={v:g}" for k, v in self.settings.to_dict().items())


def run_steps(steps: nn.ModuleList, x: torch.Tensor, state: RestorationState, obs: Observation,
              initial: InitialEstimate) -> torch.Tensor:
    """``steps`` in their order on the layers' value ``x``: what a frame on its own runs after its layers."""
    for step in steps:
        x = step(x, state, obs, initial)
    return x


def post_steps(config: RestorerConfig, refiner: EdgeRefiner | None) -> nn.ModuleDict:
    """The steps after the layers per task, in their order; ``refiner``: the model's edge refiner, if any."""
    kind = {"denoise": DenoiseRefineStep, "upsample": UpsampleRefineStep}
    refine = {} if refiner is None else {config.refiner.task: kind[config.refiner.task](refiner)}
    # the edge steps act on the samples a gated singular test found outliers in: without such a test, on none
    gated = config.uses("singular") and config.singular.gate is not None
    denoise = [EdgeSnapStep(config.edge_snap) if config.edge_snap and gated else None,
               EdgeRefitStep(config.edge_refit) if config.edge_refit and gated else None,
               refine.get("denoise"),
               FidelityBandStep(config.fidelity) if config.fidelity else None]
    upsample = [OutputHoldStep(config.upsample_hold, config.upsampling) if config.upsample_hold else None,
                refine.get("upsample")]
    return nn.ModuleDict({"denoise": nn.ModuleList(s for s in denoise if s is not None),
                          "upsample": nn.ModuleList(s for s in upsample if s is not None)})
