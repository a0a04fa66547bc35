"""Where the shared benchmark data lives.

``data_root()`` reads the environment variable ``TORCH_DEPTH_SR_DATA`` and falls back to
``../shared/data`` next to the repository (``Path(__file__).parents[2] / 'shared' / 'data'``).
Tests call ``require_data_root()``, which skips the test with a clear message when the folder
is absent.
"""

from __future__ import annotations

import os
from pathlib import Path

ENV_VAR = "TORCH_DEPTH_SR_DATA"


def data_root() -> Path:
    """Return the data root (it may not exist; see :func:`require_data_root`)."""
    env = os.environ.get(ENV_VAR)
    if env:
        return Path(env).expanduser()
    return Path(__file__).resolve().parents[2] / "shared" / "data"


def require_data_root(*subdirs: str) -> Path:
    """Return the data root, or ``pytest.skip`` when it (or one of ``subdirs``) is absent."""
    root = data_root()
    missing = [root / s for s in subdirs if not (root / s).exists()]
    if not root.is_dir() or missing:
        import pytest

        what = root if not root.is_dir() else ", ".join(str(m) for m in missing)
        pytest.skip(
            f"benchmark data not found at {what}; set {ENV_VAR}=/path/to/shared/data "
            "to run the tests that read real data"
        )
    return root


__all__ = ["ENV_VAR", "data_root", "require_data_root"]
