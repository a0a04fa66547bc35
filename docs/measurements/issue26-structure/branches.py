"""Issue 26: the branches in the forward path, by an AST scan. Lists every ``if`` statement and conditional
expression in the functions a forward runs through (the files below), with the source of its test, and marks those
whose test reads a setting (``settings``, ``config``, a group's field, or a step's flag set from the config at
construction); ``is_identity`` is counted across the whole package.

    python docs/measurements/issue26-structure/branches.py [ROOT]   # ROOT: a checkout (default: this one)
"""
from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

FILES_BEFORE = ["model.py", "layers.py", "stages.py", "initial.py", "upsampling.py", "edge_snap.py"]
FILES_AFTER = FILES_BEFORE + ["terms.py", "post_steps.py", "observation.py", "band.py", "fidelity.py"]
# names that hold settings: reading one of them in a test makes the branch a config branch
SETTINGS = re.compile(r"\b(settings|config|c|t|vp|snap|hold|terms|upsampling|refine_settings|fidelity_band|"
                      r"edge_snap|self\.(alpha|value|clean|clean_eta|gates|guided_prior|sided_fill|matches|nonlocal_|"
                      r"isotropic|task|singular|settings|refiner|guidance|initializer|upsampling|fidelity_band|"
                      r"edge_snap|refine_settings|terms|detects_singular))\b\.?|\bc\.|init_band|init_edge_band|"
                      r"tv_per_factor|use_nonlocal|use_outliers|use_singular|guided_prior|weight_clean|range_clean|"
                      r"eta_clean|output_band|refit_radius|rounds|support|gate|precondition|fixed|sided|keep")
SKIP_FUNCS = {"extra_repr", "__init__", "__repr__", "save", "load", "from_pretrained", "from_preset", "ablation",
              "preset", "layer_parameters", "values", "value"}


def scan(root: Path, files: list[str]) -> tuple[list, int]:
    pkg = root / "torch_depth_sr"
    rows = []
    for name in files:
        path = pkg / name
        if not path.is_file():
            continue
        tree = ast.parse(path.read_text())
        for fn in ast.walk(tree):
            if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)) or fn.name in SKIP_FUNCS:
                continue
            for node in ast.walk(fn):
                if isinstance(node, (ast.If, ast.IfExp)):
                    test = ast.unparse(node.test)
                    rows.append((name, node.lineno, fn.name, test, bool(SETTINGS.search(test))))
    identity = sum(p.read_text().count("is_identity") for p in pkg.rglob("*.py")
                   if "is_identity" in p.read_text() and p.name != "operators.py")
    # de-duplicate nested functions counted twice
    return sorted(set(rows)), identity


if __name__ == "__main__":
    root = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parents[3]
    files = FILES_AFTER if (root / "torch_depth_sr" / "terms.py").is_file() else FILES_BEFORE
    rows, identity = scan(root, files)
    for name, line, fn, test, config in rows:
        print(f"{'CONFIG' if config else '      '} {name}:{line} {fn}: if {test}")
    print(f"\n{sum(r[4] for r in rows)} branches on settings (heuristic, review the list), {len(rows)} in all; "
          f"'is_identity' outside operators.py: {identity}")
