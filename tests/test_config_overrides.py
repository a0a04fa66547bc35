"""apply_overrides: one dict of changes (the CLI tools' JSON flags) in the version-2 form, as dotted paths, or as
version-1 flat names converted the way a version-1 file of those settings converts."""
import pytest

from torch_depth_sr import DepthRestorer
from torch_depth_sr.config import RestorerConfig, apply_overrides, from_version1, preset_config
from torch_depth_sr.config.overrides import flat_changes
from torch_depth_sr.config.version1 import _SETS, FLAT_FIELDS, VERSION1_DEFAULTS, to_version1
from torch_depth_sr.errors import ParameterError

# one value other than the version-1 default for every version-1 field; sentinels (0 = off) where a field had one
NON_DEFAULT = dict(
    num_layers=4, lam=0.5, eta=1.0, eta_clean=1.0, gamma=2.0, mu1=1.0, mu2=0.25, isotropic=True,
    init_fill="pushpull", guided_prior=0.0, prior_on_singular=False,
    guidance_net=True, guidance_channels=8, guidance_range=2.0,
    refine_net=True, refine_channels=16, refine_layers=3, refine_task="denoise",
    init_singular=True, init_keep_observed=False, init_kernel_size=7, init_sigma_space=3.0, init_sigma_color=0.05,
    init_dt_sigma_space=3.0, init_dt_sigma_color=0.1, init_dt_iterations=2,
    upsample_init="bicubic", degradation="bicubic", upsample_init_band=0.0, upsample_init_edge_band=1.0,
    upsample_init_consistency=0.0, upsample_output_band=0.0, upsample_output_edge=0.5,
    upsample_output_edge_threshold=8.0,
    upsample_jbu={"radius": 3}, upsample_tv_per_factor=False, upsample_scale={"mu1": 6.0},
    use_nonlocal=False, use_outliers=False, use_singular=False,
    block_size=5, search_window=21, k=10, upsample_search_window=11, upsample_k=6, color_weight=100.0,
    temperature=1.0, include_self=True, match_layers=[2], rematch="exact", rematch_lattice=3,
    nl_value_weight=0.0, nl_value_var=0.5, nl_value_offset=3.0, nl_value_ridge=0.0, nl_value_range=0.0,
    nl_value_range_clean=0.0, nl_value_weight_clean=0.0,
    singular_tau=0.4, singular_sigma_floor=2.0, singular_rounds=2, singular_support=0, singular_support_tol=1.5,
    singular_line_support=False, singular_gate=0.0,
    fidelity_band=0.0,
    snap_rounds=0, snap_radius=3, snap_share=0.7, snap_sigma_color=0.1, snap_sigma_space=1.5,
    snap_refit_radius=0, snap_refit_band=1.0, snap_refit_edge=3.0,
    cg_fixed_iters=[3, 2], cg_tol=1e-4, cg_max_iter=20, precondition=False,
    implicit_backward=True, extra={"sided_fill": False},
)
# more values where a field switches a step on or off, or takes part in a condition
MORE = [
    dict(guided_prior=1.0), dict(nl_value_weight=5.0), dict(fidelity_band=2.0), dict(snap_rounds=2),
    dict(snap_refit_radius=3), dict(upsample_output_band=1.0), dict(singular_gate=0.01), dict(nl_value_range=1.0),
    dict(eta_clean=0.5), dict(nl_value_weight_clean=10.0), dict(init_fill="jbf"), dict(init_fill="domain"),
    dict(extra={}), dict(extra={"sided_fill": True}), dict(extra={"sided_fill_params": {"gap": 2.0}}),
    dict(extra={"sided_fill_params": {"ambiguous": "take", "passes": 4}}), dict(snap_sigma_space=0.0),
    dict(upsample_scale={}), dict(upsample_jbu={"sigma_color": 0.2, "first_order": False}),
    dict(use_nonlocal=True, use_outliers=False), dict(guidance_net=False), dict(refine_net=False),
]

# the version-1 named configurations (commit 046c797: ABLATIONS and PRESETS), as bases
V1_BASES = {
    "defaults": {},
    "tv": dict(use_nonlocal=False, use_outliers=False, use_singular=False, fidelity_band=0.0, nl_value_weight=0.0),
    "tv+nl": dict(use_nonlocal=True, use_outliers=False, use_singular=False, fidelity_band=0.0, nl_value_weight=0.0),
    "paper": dict(block_size=5, search_window=21, k=10, rematch="exact", init_fill="pushpull", guided_prior=0.0,
                  singular_support=0, singular_line_support=False, singular_gate=0.0, fidelity_band=0.0,
                  nl_value_weight=0.0),
    "fast": dict(search_window=11, k=10, nl_value_weight_clean=0.0, upsample_search_window=11, match_layers=(2,)),
    "refined": dict(refine_net=True, refine_channels=16, refine_task="denoise", guidance_net=True, snap_rounds=0,
                    eta_clean=1.0, nl_value_range_clean=0.0, nl_value_weight_clean=0.0, snap_sigma_color=0.3),
}


def test_every_version1_field_has_a_value_and_a_group():
    assert set(NON_DEFAULT) == FLAT_FIELDS == set(_SETS)
    assert all(NON_DEFAULT[k] != VERSION1_DEFAULTS[k] for k in NON_DEFAULT)


@pytest.mark.parametrize("field", sorted(FLAT_FIELDS))
def test_one_flat_field_on_the_defaults_is_what_version1_made_of_it(field):
    flat = {field: NON_DEFAULT[field]}
    assert apply_overrides(RestorerConfig(), flat) == from_version1(flat)


@pytest.mark.parametrize("flat", MORE, ids=str)
def test_more_flat_values_on_the_defaults(flat):
    assert apply_overrides(RestorerConfig(), flat) == from_version1(flat)


@pytest.mark.parametrize("base", sorted(V1_BASES))
def test_flat_fields_on_other_bases_as_version1(base):
    """On a base that is not the defaults (groups off, non-default settings), each flat field changes what it
    changed in version 1 and nothing else."""
    start = from_version1(V1_BASES[base])
    for flat in [{k: v} for k, v in NON_DEFAULT.items()] + MORE:
        want = from_version1({**V1_BASES[base], **flat})
        assert apply_overrides(start, flat) == want, flat


def test_version1_view_round_trips_the_presets():
    """Everything but the stream group and the edge snap's ``edge``, which version 1 did not have (the stream's model
    carries one, the fast tier the other)."""
    for name in ("full", "default", "fast", "paper", "tv", "tv+nl"):
        c = preset_config(name)
        after_version1 = {"stream": None} if c.edge_snap is None else {"stream": None, "edge_snap": {"edge": None}}
        assert from_version1(to_version1(c)) == c.replace(**after_version1), name
    assert preset_config("fast").edge_snap.edge is not None  # the case above covers one
    c = DepthRestorer.from_pretrained("denoise-fast").config
    assert c.stream is not None and from_version1(to_version1(c)) == c.replace(stream=None)


def test_flat_changes_names_only_what_changes():
    assert flat_changes({"k": 10, "snap_rounds": 0}) == {"block_matching": {"k": 10}, "edge_snap": None}
    assert flat_changes({"k": 40}) == {}
    assert flat_changes({"use_outliers": False}) == {"terms": ("nonlocal", "singular")}
    assert flat_changes({"upsample_jbu": {"radius": 3}}) == {"upsampling": {"jbu": {"radius": 3}}}
    # a setting of a group that is off leaves it off (version 1: snap_rounds=0 kept snapping off)
    assert flat_changes({"snap_radius": 3}, RestorerConfig(edge_snap=None)) == {}
    # switched on again: merged into the group's defaults
    assert flat_changes({"fidelity_band": 2.0}, RestorerConfig(fidelity=None)) == {"fidelity": {"width": 2.0}}


def test_version2_forms():
    base = preset_config("fast")
    nested = apply_overrides(base, {"block_matching": {"k": 6}, "edge_snap": None, "num_layers": 4})
    assert nested == base.replace(block_matching={"k": 6}, edge_snap=None, num_layers=4)
    assert nested.block_matching.search_window == base.block_matching.search_window == 7  # merged into the base's group
    dotted = apply_overrides(base, {"block_matching.k": 6, "edge_snap": None, "num_layers": 4})
    assert dotted == nested
    assert apply_overrides(base, {"upsampling.jbu.radius": 3, "upsampling": {"init_band": 1.0}}) == base.replace(
        upsampling={"jbu": {"radius": 3}, "init_band": 1.0})
    assert apply_overrides(base, {"guided_prior": {"weight": 1.0}}).guided_prior.weight == 1.0
    assert apply_overrides(base, {"guided_prior": None}).guided_prior is None
    assert apply_overrides(base, {"version": 2, "terms": ["nonlocal"]}).terms == ("nonlocal",)
    assert apply_overrides(base, {}) is base and apply_overrides(base, None) is base


def test_ambiguous_and_explicit_versions():
    # guided_prior: a number is the version-1 weight (0 = off), a dict or None the version-2 group
    assert apply_overrides(RestorerConfig(), {"guided_prior": 0}).guided_prior is None
    assert apply_overrides(RestorerConfig(), {"guided_prior": 1.5}).guided_prior.weight == 1.5
    # num_layers alone is the same in both
    assert apply_overrides(RestorerConfig(), {"num_layers": 3}).num_layers == 3
    assert apply_overrides(RestorerConfig(), {"version": 1, "num_layers": 3, "k": 5}) == from_version1(
        {"num_layers": 3, "k": 5})


@pytest.mark.parametrize("bad", [
    {"k": 10, "block_matching": {"k": 10}},  # mixed versions
    {"no_such_field": 1},
    {"block_matching.no_such_field": 1},
    {"version": 3},
    {"version": 1, "block_matching": {"k": 10}},
    {"version": 2, "k": 10},
    {"edge_snap": None, "edge_snap.radius": 3},
    {"k": 0},
])
def test_refused(bad):
    with pytest.raises(ParameterError):
        apply_overrides(RestorerConfig(), bad)
