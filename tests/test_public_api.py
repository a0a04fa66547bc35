"""Every module states its public names (issue 10 item 6), and each stated name exists."""
import importlib
import pkgutil

import pytest

import torch_depth_sr

MODULES = sorted(m.name for m in pkgutil.walk_packages(torch_depth_sr.__path__, "torch_depth_sr."))


@pytest.mark.parametrize("name", MODULES)
def test_module_has_all_and_every_name_exists(name):
    mod = importlib.import_module(name)
    assert hasattr(mod, "__all__"), f"{name} has no __all__"
    missing = [n for n in mod.__all__ if not hasattr(mod, n)]
    assert not missing, f"{name}.__all__ names what it does not define: {missing}"
    assert len(set(mod.__all__)) == len(mod.__all__), f"{name}.__all__ repeats a name"


def test_package_exports_what_users_need_and_not_test_oracles():
    wanted = {"DepthRestorer", "restore_depth", "RestoreDepth", "block_match", "detect_singular",
              "nonlocal_gradient", "soft_threshold", "conjugate_gradient"}
    exported = set(torch_depth_sr.__all__)
    assert wanted <= exported, sorted(wanted - exported)
    assert "block_match_reference" not in exported  # the unfold oracle is for tests
