"""Version-1 configurations: one flat object of 80 fields (``config.json`` files written before 2026-12-03, and the
shipped models trained then). :func:`version1_settings` converts one to the arguments of a :class:`~torch_depth_sr.config.RestorerConfig`
with exactly the defaults such a file had when it was written: a field a file leaves out takes the version-1
default below (not a later default), and a sentinel that switched a step off (``snap_rounds=0``,
``nl_value_weight=0``, ``fidelity_band=0``, ...) becomes that group's ``None``."""
from __future__ import annotations

from typing import Any

from ..errors import ParameterError

__all__ = ["FLAT_FIELDS", "VERSION1_DEFAULTS", "to_version1", "version1_settings"]

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


def version1_settings(values: dict) -> dict:
    """The version-2 settings (:class:`~torch_depth_sr.config.RestorerConfig`'s arguments, groups as dicts) of a
    version-1 flat dict (some or all of
    :data:`FLAT_FIELDS`; the rest take :data:`VERSION1_DEFAULTS`)."""
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
    return dict(
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


def to_version1(config: Any) -> dict:
    """The version-1 flat view of a :class:`~torch_depth_sr.config.RestorerConfig`: every field of
    :data:`FLAT_FIELDS`, a group that is off written as its version-1 sentinel (``snap_rounds=0``, ...) and the
    other fields of such a group at their version-1 defaults. :func:`~torch_depth_sr.config.from_version1` of it gives ``config`` back
    wherever version 1 can say it (not: edge refit and edge snap with different colour sigmas, settings of a group
    that is off, the stream group and the edge snap's ``edge``, which came after version 1)."""
    c, v = config, dict(VERSION1_DEFAULTS)
    v.update(num_layers=c.num_layers, degradation=c.degradation,
             use_nonlocal=c.uses("nonlocal"), use_outliers=c.uses("outliers"), use_singular=c.uses("singular"))
    w = c.weights
    v.update(lam=w.lam, eta=w.eta, gamma=w.gamma, mu1=w.mu1, mu2=w.mu2, isotropic=w.isotropic)
    v.update({name: getattr(c.block_matching, name) for name in (
        "block_size", "search_window", "k", "include_self", "match_layers", "rematch", "rematch_lattice",
        "color_weight", "temperature", "upsample_search_window", "upsample_k")})
    s = c.singular
    v.update(singular_tau=s.tau, singular_sigma_floor=s.sigma_floor, singular_rounds=s.rounds,
             singular_support=s.support, singular_support_tol=s.support_tol, singular_line_support=s.line_support,
             singular_gate=0.0 if s.gate is None else s.gate)
    so = c.solver
    v.update(cg_fixed_iters=so.fixed_iters, cg_tol=so.tol, cg_max_iter=so.max_iter, precondition=so.precondition,
             implicit_backward=so.implicit_backward)
    i = c.initial
    v.update(init_fill=i.fill, init_keep_observed=i.keep_observed, init_singular=i.singular,
             init_kernel_size=i.kernel_size, init_sigma_space=i.sigma_space, init_sigma_color=i.sigma_color,
             init_dt_sigma_space=i.dt_sigma_space, init_dt_sigma_color=i.dt_sigma_color,
             init_dt_iterations=i.dt_iterations)
    u = c.upsampling
    v.update(upsample_init=u.init, upsample_init_band=u.init_band, upsample_init_edge_band=u.init_edge_band,
             upsample_init_consistency=u.init_consistency, upsample_tv_per_factor=u.tv_per_factor,
             upsample_jbu=u.jbu.to_dict(), upsample_scale=u.multipliers.to_dict())
    if c.sided_fill is not None:
        params = {k: x for k, x in c.sided_fill.to_dict().items() if not (k == "quantiles" and x is None)}
        v["extra"] = {"sided_fill_params": params}
    elif i.fill != "pushpull":  # with push-pull the fill is off anyway: version 1 wrote nothing
        v["extra"] = {"sided_fill": False}
    if c.value_prior is None:
        v["nl_value_weight"] = 0.0
    else:
        p = c.value_prior
        v.update(nl_value_weight=p.weight, nl_value_var=p.var, nl_value_offset=p.offset, nl_value_ridge=p.ridge,
                 nl_value_range=0.0 if p.range is None else p.range)
    cs = c.clean_samples  # off = η unchanged, r and η₃ as on other samples
    v.update(eta_clean=1.0 if cs is None else cs.eta,
             nl_value_range_clean=0.0 if cs is None or cs.value_range is None else cs.value_range,
             nl_value_weight_clean=0.0 if cs is None or cs.value_weight is None else cs.value_weight)
    if c.guided_prior is None:
        v["guided_prior"] = 0.0
    else:
        v.update(guided_prior=c.guided_prior.weight, prior_on_singular=c.guided_prior.on_singular)
    v["fidelity_band"] = 0.0 if c.fidelity is None else c.fidelity.width
    if c.upsample_hold is None:
        v["upsample_output_band"] = 0.0
    else:
        h = c.upsample_hold
        v.update(upsample_output_band=h.band, upsample_output_edge=h.edge,
                 upsample_output_edge_threshold=h.edge_threshold)
    if c.edge_snap is None:
        v["snap_rounds"] = 0
    else:
        e = c.edge_snap
        v.update(snap_rounds=e.rounds, snap_radius=e.radius, snap_share=e.share, snap_sigma_color=e.sigma_color,
                 snap_sigma_space=0.0 if e.sigma_space is None else e.sigma_space)
    if c.edge_refit is None:
        v["snap_refit_radius"] = 0
    else:
        r = c.edge_refit
        v.update(snap_refit_radius=r.radius, snap_refit_band=r.band, snap_refit_edge=r.edge)
        if c.edge_snap is None:  # one colour sigma for both steps in version 1
            v["snap_sigma_color"] = r.sigma_color
    if c.guidance is not None:
        v.update(guidance_net=True, guidance_channels=c.guidance.channels, guidance_range=c.guidance.range)
    if c.refiner is not None:
        v.update(refine_net=True, refine_channels=c.refiner.channels, refine_layers=c.refiner.layers,
                 refine_task=c.refiner.task)
    return v


# the version-2 top-level fields each version-1 field sets
_SETS: dict = {
    **dict.fromkeys(("num_layers",), ("num_layers",)), "degradation": ("degradation",),
    **dict.fromkeys(("use_nonlocal", "use_outliers", "use_singular"), ("terms",)),
    **dict.fromkeys(("lam", "eta", "gamma", "mu1", "mu2", "isotropic"), ("weights",)),
    **dict.fromkeys(("eta_clean", "nl_value_range_clean", "nl_value_weight_clean"), ("clean_samples",)),
    "init_fill": ("initial", "sided_fill"),
    **dict.fromkeys(("init_singular", "init_keep_observed", "init_kernel_size", "init_sigma_space", "init_sigma_color",
                     "init_dt_sigma_space", "init_dt_sigma_color", "init_dt_iterations"), ("initial",)),
    **dict.fromkeys(("guided_prior", "prior_on_singular"), ("guided_prior",)),
    **dict.fromkeys(("guidance_net", "guidance_channels", "guidance_range"), ("guidance",)),
    **dict.fromkeys(("refine_net", "refine_channels", "refine_layers", "refine_task"), ("refiner",)),
    **dict.fromkeys(("upsample_init", "upsample_init_band", "upsample_init_edge_band", "upsample_init_consistency",
                     "upsample_jbu", "upsample_tv_per_factor", "upsample_scale"), ("upsampling",)),
    **dict.fromkeys(("upsample_output_band", "upsample_output_edge", "upsample_output_edge_threshold"),
                    ("upsample_hold",)),
    **dict.fromkeys(("block_size", "search_window", "k", "upsample_search_window", "upsample_k", "color_weight",
                     "temperature", "include_self", "match_layers", "rematch", "rematch_lattice"),
                    ("block_matching",)),
    **dict.fromkeys(("nl_value_weight", "nl_value_var", "nl_value_offset", "nl_value_ridge", "nl_value_range"),
                    ("value_prior",)),
    **dict.fromkeys(("singular_tau", "singular_sigma_floor", "singular_rounds", "singular_support",
                     "singular_support_tol", "singular_line_support", "singular_gate"), ("singular",)),
    "fidelity_band": ("fidelity",),
    **dict.fromkeys(("snap_rounds", "snap_radius", "snap_share", "snap_sigma_space"), ("edge_snap",)),
    "snap_sigma_color": ("edge_snap", "edge_refit"),
    **dict.fromkeys(("snap_refit_radius", "snap_refit_band", "snap_refit_edge"), ("edge_refit",)),
    **dict.fromkeys(("cg_fixed_iters", "cg_tol", "cg_max_iter", "precondition", "implicit_backward"), ("solver",)),
    "extra": ("sided_fill",),
}
