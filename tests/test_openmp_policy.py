"""Importing the package before torch shortens the spin of torch's idle OpenMP threads (torch_depth_sr/_openmp.py);
what the environment or an earlier ``import torch`` chose is kept."""
import os
import subprocess
import sys

import pytest

_READ = "import os, torch_depth_sr; print(os.environ.get('GOMP_SPINCOUNT'), torch_depth_sr._openmp.SPIN_SET)"


def _run(code: str, **env: str) -> str:
    base = {k: v for k, v in os.environ.items() if k not in ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT")}
    out = subprocess.run([sys.executable, "-c", code], env={**base, **env}, capture_output=True, text=True,
                         check=True)
    return out.stdout.split()[-2] + " " + out.stdout.split()[-1]


def test_importing_the_package_first_sets_a_short_spin():
    assert _run(_READ) == "10000 True"


@pytest.mark.parametrize("env,expected", [({"OMP_WAIT_POLICY": "ACTIVE"}, "None False"),
                                          ({"GOMP_SPINCOUNT": "300000"}, "300000 False")])
def test_a_policy_of_the_environment_is_kept(env, expected):
    assert _run(_READ, **env) == expected


def test_torch_loaded_first_keeps_its_policy():
    assert _run("import torch; " + _READ) == "None False"
