"""Issue 26: branches on settings in the forward path, by an AST scan (the design review's method, section 1.4).

Lists every ``if`` statement and conditional expression in the functions a forward runs through (construction —
``__init__`` and the builders of term and step lists —, argument checks at the public boundary, ``extra_repr`` and
saving/loading left out), with the source of its test, and classes each: ``config`` when the test reads a setting
or a value that exists only because of one (the gate's ``clean``, ``sided_fill``, the guidance network, a JBU that
the settings asked for), ``task`` for the one dispatch on ``K.is_identity``, else data / argument / instrumentation.
Also counts ``is_identity`` outside ``operators.py``.

    python docs/measurements/issue26-structure/branches.py [ROOT]   # ROOT: a checkout (default: this one)
"""
from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

BEFORE = ["model.py", "layers.py", "stages.py", "initial.py", "upsampling.py", "edge_snap.py"]
AFTER = BEFORE + ["terms.py", "post_steps.py", "observation.py", "band.py", "fidelity.py"]
NOT_FORWARD = {
    "__init__", "extra_repr", "save", "load", "from_pretrained", "from_preset", "ablation", "preset",
    "layer_parameters", "values", "value", "restore_with_details", "_run_tensors", "restore_depth", "_check_fill",
    "_is_model_input", "_check_model_input", "_is_integer_dtype", "_infer_factor", "_load_state_file",
    "_check_state_matches", "_rename_legacy_keys", "_inv_softplus", "cg_iterations_for",
    # builders, run once when the model is built
    "terms_for", "match_steps", "_matched", "_value_prior", "_clean_samples", "post_steps", "initial_stages",
    "_range_sigma", "_weight_on_clean_samples", "_edge_evidence_config",
}
CONFIG = re.compile(
    r"\b(settings|config|c|t|vp|snap|terms|refine_settings|upsampling|self\.(guidance|edge_snap|fidelity_band|"
    r"initializer|refiner|detects_singular|settings))\.|\bsided_fill\b|\bjbu is None\b|\bclean\b|\bctx\.(clean|prior|"
    r"guidance|supported)|\bbeta\b|\bdiag is not None and ctx|init_band|init_edge_band|consistency|use_noise_band|"
    r"value_prior|refining|snapping|self\.guidance is None|line_support|\bfixed\b")
TASK = re.compile(r"is_identity")


def scan(root: Path) -> tuple[list, int]:
    pkg = root / "torch_depth_sr"
    files = AFTER if (pkg / "terms.py").is_file() else BEFORE
    rows = set()
    for name in files:
        path = pkg / name
        if not path.is_file():
            continue
        for fn in ast.walk(ast.parse(path.read_text())):
            if not isinstance(fn, ast.FunctionDef) or fn.name in NOT_FORWARD:
                continue
            for node in ast.walk(fn):
                if isinstance(node, (ast.If, ast.IfExp)):
                    test = ast.unparse(node.test)
                    kind = "task" if TASK.search(test) else "config" if CONFIG.search(test) else "other"
                    rows.add((name, node.lineno, fn.name, test, kind))
    identity = sum(p.read_text().count("is_identity") for p in pkg.rglob("*.py") if p.name != "operators.py")
    return sorted(rows), identity


if __name__ == "__main__":
    root = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parents[3]
    rows, identity = scan(root)
    for name, line, fn, test, kind in rows:
        print(f"{kind:6s} {name}:{line} {fn}: {test}")
    counts = {k: sum(r[4] == k for r in rows) for k in ("config", "task", "other")}
    print(f"\nforward path: {counts['config']} branches on settings, {counts['task']} on the task, "
          f"{counts['other']} on data/arguments/instrumentation; 'is_identity' outside operators.py: {identity}")
