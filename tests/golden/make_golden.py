"""Generator of the golden outputs in this folder (``inputs.pt``, ``outputs.pt``), read by ``tests/test_golden.py``.

It was run ONCE, with the code at commit 046c797 (before issue 26's refactor of the model's internals and config),
on the CPU, as

    OMP_NUM_THREADS=1 python tests/golden/make_golden.py

Do NOT re-run it to "fix" a failing ``test_golden.py``: the stored outputs are the numbers of the code before the
refactor, and a refactor that changes them has changed the results (issue 26: "every output, gradient and benchmark
figure stays bit for bit what it is"). Re-run it only when a change of the numbers is intended, reviewed and stated
(then say so in the commit message, with the commit the new goldens were made at).

It uses the API of 046c797: named configurations by ``DepthRestorer.ablation(name)`` (``paper``, ``tv``, ``tv+nl``)
and ``DepthRestorer.preset("fast")``; the test builds them with ``DepthRestorer.from_preset(name)``.

**The ``named/fast/*`` entries were regenerated once, on purpose (issue 27, "speed tiers").** The preset ``fast``
was redefined: it is now the fast speed tier, the shipped model ``denoise-fast`` (3 layers trained end to end, one
block-matching pass on x⁰ in a 7×7 window, 10 matches, a small trained edge refiner; ``DepthRestorer.from_preset("fast")``
loads it), where it
was an 8-layer frozen variant of the defaults (11×11 window, 10 matches, one re-match). Its outputs changed by
design, so only its three entries were made again, with

    OMP_NUM_THREADS=1 python tests/golden/make_golden.py --fast-only

which keeps every other entry and the inputs byte for byte (the other 39 cases still hold the numbers of 046c797,
and the speed work of issue 27 keeps them bit for bit: kernels changed only where the result is the same).

**They were regenerated a second time, on purpose (issue 27, tenth stop, 2026-12-04).** ``denoise-fast``'s edge
refiner was retrained with near-clean noise as well (σ 0.5 beside 3, 5 and 8; 16 channels, 3 layers instead of 8 and
2): the old one made a near-clean map worse (the do-no-harm test's Art crop at σ 0.3: 0.3121 against the input's
0.2987). The layers are unchanged; the same ``--fast-only`` command made the three entries again, every other entry
kept byte for byte.

**Entries added later, on purpose (issue 27, tenth stop, 2026-12-04): ``shipped/denoise-default/*`` and
``shipped/denoise-best/*``**, the ``default`` and ``best`` speed tiers, which did not exist at 046c797. They were made
with the code of that stop, every other entry and the inputs kept byte for byte, by

    OMP_NUM_THREADS=1 python tests/golden/make_golden.py --add-shipped denoise-default denoise-best

**``shipped/denoise-default/*`` and ``shipped/denoise-best/*`` were made again, on purpose (issue 27, eleventh stop,
2026-12-05).** The ``default`` and ``best`` tiers' edge refiners were trained further from their shipped weights
(selection on validation MAE; docs/pretrained.md); ``--add-shipped denoise-default denoise-best`` rewrote their
entries: the denoising outputs changed, the x2 / x4 area ones (where the refiners do not run) and every other entry
stayed byte for byte.

**``shipped/denoise-default/*`` were made again, on purpose (issue 27, twelfth stop, 2026-12-05).** The ``default``
tier's singular test takes neighbour support within 4 noise σ instead of 3 (``singular.support_tol`` in its
config.json, by the rule in docs/measurements/issue27-tiers/twelfth-stop/rule-support-tol.md: two near-clean 2006
crops came out 3–4 times worse); ``OMP_NUM_THREADS=1 python tests/golden/make_golden.py --add-shipped
denoise-default`` rewrote its entries; its denoising depth and confidence were kept from that run, its x2 / x4 area entries
(which the singular test does not touch: the same values with either tolerance) and every other entry as they were.

**``named/fast/*`` were regenerated a third time, and ``shipped/denoise-fast/*`` added, on purpose (issue 27,
fourteenth stop, 2026-12-05).** The ``fast`` tier is now ``denoise-fast2`` (2 trained layers, snapping near depth
edges only; chosen by docs/measurements/issue27-tiers/fourteenth-stop/rule-lighter-fast.md); the 3-layer
``denoise-fast`` stays shipped as the stream's model and keeps its numbers under its own key. Made by

    OMP_NUM_THREADS=1 python tests/golden/make_golden.py --add-shipped denoise-fast
    OMP_NUM_THREADS=1 python tests/golden/make_golden.py --fast-only

every other entry and the inputs kept byte for byte. The new ``shipped/denoise-fast/*`` entries are bit for bit what
the code before this stop (3be6d3d) gives for ``from_preset("fast")``; the old ``named/fast/*`` entries differed from
that by at most 4.6e-5 (float rounding of earlier stops' kernels, within the test's tolerance).

**``shipped/denoise-best/*`` were made again, on purpose (issue 27, seventeenth stop, 2026-12-05).** The ``best``
tier re-ranks its matches with a step-3 lattice of its 21×21 window instead of step 2 (``block_matching.
rematch_lattice`` in its config.json, by the rule in docs/measurements/issue27-tiers/seventeenth-stop/
rule-best-rematching.md); ``OMP_NUM_THREADS=1 python tests/golden/make_golden.py --add-shipped denoise-best``
rewrote its entries, every other entry and the inputs kept byte for byte. The same stop's re-ranking of small
windows by the exact search's kernel (``refine_cpu._MASKED_UP_TO``) moved the ``default`` tier's outputs by float
rounding only, within the test's tolerance, so its entries were kept then (they were made again for its refiner, next).

**``shipped/denoise-default/*`` were made again, on purpose (issue 27, seventeenth stop, 2026-12-05).** The
``default`` tier's edge refiner is now the twelfth stop's 24-channel one (by the rule in
docs/measurements/issue27-tiers/seventeenth-stop/rule-default-r24-again.md); ``OMP_NUM_THREADS=1 python
tests/golden/make_golden.py --add-shipped denoise-default`` rewrote its entries (their denoising outputs changed),
every other entry and the inputs kept byte for byte.

Inputs (tiny, deterministic; stored so that the test does not depend on the scene generator): one synthetic scene
(``make_scene(32, 40, seed=7)``), its colour image at 32x40 (the output size of every task); denoising: Gaussian noise
sigma = 3, two holes, five impulses and five flying pixels; guided upsampling x2 and x4: the ground truth area-averaged
(``area``) or antialiased-bicubic resized (``bicubic``), Gaussian noise sigma = 3, one hole of two pixels (x2).
"""
from __future__ import annotations

import sys
from pathlib import Path

import torch
import torch.nn.functional as F

HERE = Path(__file__).resolve().parent
NAMED = ("default", "fast", "paper", "tv", "tv+nl")
SHIPPED = ("denoise", "denoise-guided", "denoise-refined", "upsample", "upsample-area", "upsample-x4",
           "upsample-x4-refined")
BICUBIC_MODELS = ("upsample", "upsample-x4", "upsample-x4-refined")  # also on bicubic-downsampled input


def make_inputs() -> dict:
    from torch_depth_sr.datasets.synthetic import make_scene

    s = make_scene(32, 40, seed=7)
    gt, rgb = s["gt"][None].float(), s["rgb"][None].float()  # (1,1,32,40), (1,3,32,40)
    g = torch.Generator().manual_seed(26)
    out = {"rgb": rgb, "gt": gt}
    y = gt + 3.0 * torch.randn(gt.shape, generator=g)
    y[..., 6:9, 10:14] = 0  # holes
    y[..., 22:24, 30:33] = 0
    for r, c, d in ((4, 4, 35.0), (12, 27, -30.0), (18, 8, 40.0), (27, 17, -35.0), (29, 36, 30.0)):  # impulses
        y[..., r, c] += d
    jump = (gt[..., :, 2:] - gt[..., :, :-2]).abs() > 20  # flying pixels: the mean of both sides of a depth edge
    for r, c in jump[0, 0].nonzero()[::5][:5].tolist():
        y[..., r, c + 1] = 0.5 * (gt[..., r, c] + gt[..., r, c + 2])
    out["denoise"] = y.clamp_min(0)
    for f in (2, 4):
        for deg in ("area", "bicubic"):
            lr = (F.avg_pool2d(gt, f) if deg == "area" else
                  F.interpolate(gt, size=(32 // f, 40 // f), mode="bicubic", antialias=True, align_corners=False))
            y = lr + 3.0 * torch.randn(lr.shape, generator=g)
            if f == 2:
                y[..., 5, 6:8] = 0
            out[f"x{f}/{deg}"] = y.clamp_min(0)
    return out


def cases() -> list[tuple[str, str, str]]:
    """(kind, name, task): every named configuration and shipped model on denoising and x2 / x4 area upsampling,
    and the bicubic-trained ones on bicubic x2 / x4 too."""
    out = []
    for kind, names in (("named", NAMED), ("shipped", SHIPPED)):
        for name in names:
            for task in ("denoise", "x2/area", "x4/area"):
                out.append((kind, name, task))
            if name in BICUBIC_MODELS:
                out += [(kind, name, "x2/bicubic"), (kind, name, "x4/bicubic")]
    return out


def _build_at_046c797(kind: str, name: str):
    from torch_depth_sr import DepthRestorer

    if kind == "shipped":
        return DepthRestorer.from_pretrained(name)
    if name == "default":
        return DepthRestorer()
    if name == "fast":
        return DepthRestorer.preset("fast")
    return DepthRestorer.ablation(name)


def refresh_fast() -> None:
    """Make the ``named/fast/*`` entries again with the current code (``from_preset("fast")``), every other entry
    and the inputs kept as stored (see the module docstring)."""
    from torch_depth_sr import DepthRestorer

    _rewrite({"named/fast": DepthRestorer.from_preset("fast")})


def add_shipped(names: list[str]) -> None:
    """Store the ``shipped/<name>/*`` entries of shipped models made after 046c797 (denoising and x2 / x4 area
    upsampling) with the current code; every other entry and the inputs kept as stored (the module docstring)."""
    from torch_depth_sr import DepthRestorer

    _rewrite({f"shipped/{name}": DepthRestorer.from_pretrained(name) for name in names})


def _rewrite(models: dict) -> None:
    """(Re)make the denoising and x2 / x4 area entries under each key prefix (``"named/fast"``) with its model, on one
    thread; every other entry and the inputs stay as stored."""
    torch.set_num_threads(1)
    inputs = torch.load(HERE / "inputs.pt", weights_only=True)
    outputs = torch.load(HERE / "outputs.pt", weights_only=True)
    for prefix, model in models.items():
        for task in ("denoise", "x2/area", "x4/area"):
            _store(outputs, f"{prefix}/{task}", model, inputs, task)
    torch.save(outputs, HERE / "outputs.pt")


def _store(outputs: dict, key: str, model, inputs: dict, task: str) -> None:
    """One case's outputs: the depth, and the confidence of denoising; the networks in float32, as the test runs them
    (on a processor with AMX ``network_precision="auto"`` would pick bfloat16)."""
    from torch_depth_sr.precision import network_precision

    with network_precision("float32"):
        r = model.restore_with_details(inputs[task], inputs["rgb"])
    outputs[f"{key}/depth"] = r.depth.detach().clone()
    if task == "denoise":
        outputs[f"{key}/confidence"] = r.confidence.detach().clone()
    print(key, file=sys.stderr)


def main() -> None:
    import torch_depth_sr

    print("package:", torch_depth_sr.__file__, "torch", torch.__version__, file=sys.stderr)
    torch.set_num_threads(1)
    inputs = make_inputs()
    outputs = {}
    for kind, name, task in cases():
        _store(outputs, f"{kind}/{name}/{task}", _build_at_046c797(kind, name), inputs, task)
    torch.save(inputs, HERE / "inputs.pt")
    torch.save(outputs, HERE / "outputs.pt")
    print(f"{len(cases())} cases, {len(outputs)} tensors", file=sys.stderr)


if __name__ == "__main__":
    if "--fast-only" in sys.argv[1:]:
        refresh_fast()
    elif sys.argv[1:2] == ["--add-shipped"]:
        add_shipped(sys.argv[2:])
    else:
        main()
