"""Version-1 configurations: one flat object of 80 fields (``config.json`` files written before 2026-12-03, and the
shipped models trained then). :func:`from_version1` converts one to a :class:`~torch_depth_sr.config.RestorerConfig`
with exactly the defaults such a file had when it was written: a field a file leaves out takes the version-1
default below (not a later default), and a sentinel that switched a step off (``snap_rounds=0``,
``nl_value_weight=0``, ``fidelity_band=0``, ...) becomes that group's ``None``."""
from __future__ import annotations

from typing import Any

from ..errors import ParameterError

__all__ = ["FLAT_FIELDS", "VERSION1_DEFAULTS", "from_version1"]

# the version-1 defaults, as they stood when the format was retired (commit 046c797)
VERSION1_DEFAULTS: dict = dict(
    num_layers=8, lam=1.0, eta=2.0, eta_clean=0.25, gamma=3.0, mu1=2.0, mu2=0.5, isotropic=False,
    init_fill="domain", guided_prior=3.2, prior_on_singular=True,
    guidance_net=False, guidance_channels=16, guidance_range=4.0,
    refine_net=False, refine_channels=32, refine_layers=6, refine_task="upsample",
    init_singular=False, init_keep_observed=True, init_kernel_size=11, init_sigma_space=6.0, init_sigma_color=0.025,
    init_dt_sigma_space=6.0, init_dt_sigma_color=0.2, init_dt_iterations=1,
    upsample_init="jbu", degradation="area", upsample_init_band=3.0, upsample_init_edge_band=0.5,
    upsample_init_consistency=2.0, upsample_output_band=3.0, upsample_output_edge=1.0,
    upsample_output_edge_threshold=16.0,
    upsample_jbu={"radius": 2, "sigma_space": 1.0, "sigma_color": 0.1, "first_order": True},
    upsample_tv_per_factor=True, upsample_scale={"mu1": 3.0, "mu2": 3.0},
    use_nonlocal=True, use_outliers=True, use_singular=True,
    block_size=3, search_window=15, k=40, upsample_search_window=21, upsample_k=10, color_weight=400.0,
    temperature=0.5, include_self=False, match_layers=(2, 5), rematch="refine", rematch_lattice=2,
    nl_value_weight=10.0, nl_value_var=0.25, nl_value_offset=6.0, nl_value_ridge=1.0, nl_value_range=3.0,
    nl_value_range_clean=1.0, nl_value_weight_clean=30.0,
    singular_tau=0.5, singular_sigma_floor=2.5, singular_rounds=3, singular_support=3, singular_support_tol=2.0,
    singular_line_support=True, singular_gate=0.002,
    fidelity_band=4.0,
    snap_rounds=1, snap_radius=2, snap_share=0.6, snap_sigma_color=0.235, snap_sigma_space=0.0,
    snap_refit_radius=5, snap_refit_band=1.5, snap_refit_edge=2.0,
    cg_fixed_iters=(5, 4, 3, 3, 3, 2, 2, 1), cg_tol=1e-3, cg_max_iter=50, precondition=True,
    implicit_backward=False, extra={},
)
FLAT_FIELDS = frozenset(VERSION1_DEFAULTS)
# a version-1 upsample_scale named only the multipliers that differ from 1
_UNIT_MULTIPLIERS = dict(lam=1.0, eta=1.0, gamma=1.0, mu1=1.0, mu2=1.0)
_SIDED = dict(gap=4.0, min_share=0.75, passes=8, choice_sigma_space=1.5, ambiguous="mix")


def from_version1(values: dict):
    """The version-2 :class:`~torch_depth_sr.config.RestorerConfig` of a version-1 flat dict (some or all of
    :data:`FLAT_FIELDS`; the rest take :data:`VERSION1_DEFAULTS`)."""
    from .restorer import RestorerConfig

    unknown = set(values) - FLAT_FIELDS
    if unknown:
        raise ParameterError("keys", sorted(unknown), f"version-1 RestorerConfig fields ({', '.join(sorted(FLAT_FIELDS))})",
                             "Remove or rename the unknown keys.")
    v = {**VERSION1_DEFAULTS, **values}
    terms = tuple(t for t, on in (("nonlocal", v["use_nonlocal"]), ("outliers", v["use_outliers"]),
                                  ("singular", v["use_singular"])) if _flag(on, "use_" + t))
    extra = v["extra"]
    if not isinstance(extra, dict) or set(extra) - {"sided_fill", "sided_fill_params"}:
        raise ParameterError("extra", extra, "a dict with some of 'sided_fill' (bool) and 'sided_fill_params' (dict)")
    sided = None
    if bool(extra.get("sided_fill", True)) and v["init_fill"] != "pushpull":
        params = dict(extra.get("sided_fill_params", {})) if isinstance(extra.get("sided_fill_params", {}), dict) \
            else extra["sided_fill_params"]
        if isinstance(params, dict) and "ambiguous" in params and params["ambiguous"] != "mix":
            params["ambiguous"] = "take"
        sided = {**_SIDED, **params} if isinstance(params, dict) else params
    clean = None
    if v["eta_clean"] != 1.0 or v["nl_value_range_clean"] != 0 or v["nl_value_weight_clean"] != 0:
        clean = dict(eta=v["eta_clean"], value_range=_off_at_zero(v["nl_value_range_clean"]),
                     value_weight=_off_at_zero(v["nl_value_weight_clean"]))
    return RestorerConfig(
        num_layers=v["num_layers"], degradation=v["degradation"], terms=terms,
        weights=dict(lam=v["lam"], eta=v["eta"], gamma=v["gamma"], mu1=v["mu1"], mu2=v["mu2"],
                     isotropic=v["isotropic"]),
        block_matching=dict(block_size=v["block_size"], search_window=v["search_window"], k=v["k"],
                            include_self=v["include_self"], match_layers=v["match_layers"], rematch=v["rematch"],
                            rematch_lattice=v["rematch_lattice"], color_weight=v["color_weight"],
                            temperature=v["temperature"], upsample_search_window=v["upsample_search_window"],
                            upsample_k=v["upsample_k"]),
        singular=dict(tau=v["singular_tau"], sigma_floor=v["singular_sigma_floor"], rounds=v["singular_rounds"],
                      support=v["singular_support"], support_tol=v["singular_support_tol"],
                      line_support=v["singular_line_support"], gate=_off_at_zero(v["singular_gate"])),
        solver=dict(fixed_iters=v["cg_fixed_iters"], tol=v["cg_tol"], max_iter=v["cg_max_iter"],
                    precondition=v["precondition"], implicit_backward=v["implicit_backward"]),
        initial=dict(fill=v["init_fill"], keep_observed=v["init_keep_observed"], singular=v["init_singular"],
                     kernel_size=v["init_kernel_size"], sigma_space=v["init_sigma_space"],
                     sigma_color=v["init_sigma_color"], dt_sigma_space=v["init_dt_sigma_space"],
                     dt_sigma_color=v["init_dt_sigma_color"], dt_iterations=v["init_dt_iterations"]),
        upsampling=dict(init=v["upsample_init"], init_band=v["upsample_init_band"],
                        init_edge_band=v["upsample_init_edge_band"],
                        init_consistency=v["upsample_init_consistency"], tv_per_factor=v["upsample_tv_per_factor"],
                        jbu=_dict_field(v["upsample_jbu"], "upsample_jbu"),
                        multipliers={**_UNIT_MULTIPLIERS, **_dict_field(v["upsample_scale"], "upsample_scale")}),
        sided_fill=sided,
        value_prior=None if v["nl_value_weight"] == 0 else dict(
            weight=v["nl_value_weight"], var=v["nl_value_var"], offset=v["nl_value_offset"],
            ridge=v["nl_value_ridge"], range=_off_at_zero(v["nl_value_range"])),
        clean_samples=clean,
        guided_prior=None if v["guided_prior"] == 0 else dict(weight=v["guided_prior"],
                                                              on_singular=v["prior_on_singular"]),
        fidelity=None if v["fidelity_band"] == 0 else dict(width=v["fidelity_band"]),
        upsample_hold=None if v["upsample_output_band"] == 0 else dict(
            band=v["upsample_output_band"], edge=v["upsample_output_edge"],
            edge_threshold=v["upsample_output_edge_threshold"]),
        edge_snap=None if v["snap_rounds"] == 0 else dict(
            rounds=v["snap_rounds"], radius=v["snap_radius"], share=v["snap_share"], sigma_color=v["snap_sigma_color"],
            sigma_space=_off_at_zero(v["snap_sigma_space"])),
        edge_refit=None if v["snap_refit_radius"] == 0 else dict(
            radius=v["snap_refit_radius"], band=v["snap_refit_band"], edge=v["snap_refit_edge"],
            sigma_color=v["snap_sigma_color"]),
        guidance=dict(channels=v["guidance_channels"], range=v["guidance_range"]) if _flag(
            v["guidance_net"], "guidance_net") else None,
        refiner=dict(channels=v["refine_channels"], layers=v["refine_layers"], task=v["refine_task"]) if _flag(
            v["refine_net"], "refine_net") else None,
    )


def _off_at_zero(v: Any) -> Any:
    """Version 1 switched a setting off with 0; version 2 with None."""
    return None if isinstance(v, (int, float)) and not isinstance(v, bool) and v == 0 else v


def _flag(v: Any, name: str) -> bool:
    if not isinstance(v, bool):
        raise ParameterError(name, v, "True or False")
    return v


def _dict_field(v: Any, name: str) -> dict:
    if not isinstance(v, dict):
        raise ParameterError(name, v, "a dict")
    return v
