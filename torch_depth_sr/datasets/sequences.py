"""Procedural RGB-D *sequences* with ground truth, for the stream track (``bench --track stream``).

A sequence is a static world (a :func:`~torch_depth_sr.datasets.synthetic.make_scene` larger than the frame), seen
by a camera that holds still or pans by whole pixels, with moving objects ("movers": textured rectangles and discs
nearer than the world, each moving at its own constant velocity and bouncing off the frame's borders). The sensor
is a stereo-like depth camera in millimetres (``Z = C / d`` with ``d`` the scene's disparity-like value and ``C`` =
100 000, so about 0.43–5 m), redrawn every frame from its own seed:

* Gaussian noise of ``disparity_noise`` on the disparity (so the depth noise grows like Z²);
* holes: the stereo shadow left of every rising depth edge (width ∝ the disparity jump), dark surfaces that drop
  out with probability ``dark_dropout`` per frame, random ellipses (``blob_coverage`` of the frame) and single
  pixels (``pixel_dropout``);
* flying pixels: ``flying`` of the pixels at depth edges take a value between the two sides;
* impulses: ``impulses`` of the pixels take a uniform value over the frame's range;
* quantisation to whole millimetres (uint16, 0 = no measurement).

Everything is a pure function of the arguments (numpy PCG64 seeded by ``[seed, frame]``).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Iterable
import cv2
import numpy as np

from ..errors import DepthSRError
from .synthetic import make_scene

__all__ = ["DEPTH_CONSTANT", "SensorModel", "make_sequence", "recipe_sequences", "STREAM_SEQUENCES",
           "TUNING_SEQUENCES"]

DEPTH_CONSTANT = 100_000.0  # Z [mm] = C / disparity


@dataclass(frozen=True)
class SensorModel:
    """The per-frame degradation of a sequence (module docstring); shares are of the frame's pixels."""

    disparity_noise: float = 0.35
    shadow: float = 0.05  # stereo-shadow width in px per grey level of disparity jump (at most 6 px)
    dark_dropout: float = 0.5
    dark_level: float = 0.15
    blob_coverage: float = 0.02
    pixel_dropout: float = 0.01
    flying: float = 0.25
    impulses: float = 0.001


@dataclass(frozen=True)
class SequenceSpec:
    """A named sequence of the stream track."""

    name: str
    seed: int
    camera: str = "static"  # "static" or "pan" (pans by pan_speed px per frame for pan_frames frames, then holds)
    movers: int = 2
    speed: tuple = (1.0, 3.0)  # px per frame
    pan_frames: int = 10
    pan_speed: tuple = (1, 1)  # (dy, dx) px per frame
    sensor: SensorModel = field(default_factory=SensorModel)


STREAM_SEQUENCES = (
    SequenceSpec("static-2movers", seed=1, camera="static", movers=2),
    SequenceSpec("pan-then-hold", seed=2, camera="pan", movers=1),
    SequenceSpec("static-busy", seed=3, camera="static", movers=3, speed=(2.0, 4.0),
                 sensor=SensorModel(disparity_noise=0.5, dark_dropout=0.7, blob_coverage=0.04)),
)
"""The evaluated sequences of ``bench --track stream`` (fixed seeds)."""

TUNING_SEQUENCES = tuple(SequenceSpec(f"tune-{s.name}", seed=100 + s.seed, camera=s.camera, movers=s.movers,
                                      speed=s.speed, pan_frames=s.pan_frames, sensor=s.sensor)
                         for s in STREAM_SEQUENCES)
"""Other scenes with the same recipes, on which the baselines' settings are tuned (never the evaluated ones)."""


def recipe_sequences(seeds: Iterable[int]) -> tuple:
    """The recipes of :data:`STREAM_SEQUENCES` with other ``seeds`` (new scenes, movers and noise), named
    ``recipe@seed``, seed by seed: how the stream track's figures carry over to other scenes
    (``bench --track stream --seeds``). Seeds 1–3 are the evaluated sequences, 101–103 the tuning ones.

    Examples:
        >>> [s.name for s in recipe_sequences([200])]
        ['static-2movers@200', 'pan-then-hold@200', 'static-busy@200']
    """
    return tuple(replace(s, name=f"{s.name}@{seed}", seed=int(seed)) for seed in seeds for s in STREAM_SEQUENCES)


def _mover(rng: np.random.Generator, h: int, w: int, speed: tuple) -> dict:
    kind = "rect" if rng.random() < 0.5 else "disc"
    size = rng.uniform(0.12, 0.22) * min(h, w)
    angle = rng.uniform(0, 2 * np.pi)
    v = rng.uniform(*speed)
    return dict(kind=kind, ry=size * rng.uniform(0.7, 1.3), rx=size * rng.uniform(0.7, 1.3),
                y=rng.uniform(0.25, 0.75) * h, x=rng.uniform(0.25, 0.75) * w, vy=v * np.sin(angle),
                vx=v * np.cos(angle), disp=rng.uniform(150, 215), slope=rng.uniform(-0.3, 0.3, 2),
                colour=rng.uniform(0.05, 0.95, 3), stripes=rng.uniform(0.1, 0.4), phase=rng.uniform(0, 6.3))


def _mover_at(m: dict, t: int, h: int, w: int) -> tuple[float, float]:
    """Position at frame t, bouncing off the borders (a triangle wave)."""
    def bounce(p0, v, lo, hi):
        span = hi - lo
        p = (p0 - lo + v * t) % (2 * span)
        return lo + (p if p <= span else 2 * span - p)
    return bounce(m["y"], m["vy"], m["ry"] * 0.5, h - m["ry"] * 0.5), bounce(m["x"], m["vx"], m["rx"] * 0.5,
                                                                              w - m["rx"] * 0.5)


def _draw_mover(m: dict, cy: float, cx: float, disp: np.ndarray, rgb: np.ndarray, moving: np.ndarray) -> None:
    h, w = disp.shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    dy, dx = (yy - cy) / m["ry"], (xx - cx) / m["rx"]
    inside = (np.abs(dy) <= 1) & (np.abs(dx) <= 1) if m["kind"] == "rect" else dy ** 2 + dx ** 2 <= 1
    dv = m["disp"] + m["slope"][0] * (yy - cy) + m["slope"][1] * (xx - cx)
    inside &= dv > disp
    disp[inside] = dv[inside]
    tex = 0.5 + 0.5 * np.sin(m["stripes"] * (xx - cx) + m["phase"]) * np.cos(m["stripes"] * (yy - cy))
    col = np.clip(m["colour"][None, None, :] * (0.75 + 0.25 * tex[..., None]), 0, 1)
    rgb[inside] = col[inside]
    moving |= inside


def _sensor(disp: np.ndarray, rgb: np.ndarray, s: SensorModel, rng: np.random.Generator) -> np.ndarray:
    """One frame of the sensor: depth in mm, uint16, 0 = no measurement."""
    h, w = disp.shape
    noisy = np.clip(disp + s.disparity_noise * rng.standard_normal(disp.shape), 1.0, None)
    z = DEPTH_CONSTANT / noisy
    hole = np.zeros((h, w), bool)
    jump = disp[:, 1:] - disp[:, :-1]  # > 0: the right side is nearer (it shadows the left)
    width = np.clip(np.floor(jump * s.shadow), 0, 6).astype(int)
    for k in range(int(width.max(initial=0))):
        src = width > k  # (H, W-1): shadow reaches k px left of column j
        hole[:, : w - 1 - k] |= src[:, k:]
    lum = rgb @ np.array([0.299, 0.587, 0.114], np.float32)
    hole |= (lum < s.dark_level) & (rng.random((h, w)) < s.dark_dropout)
    if s.blob_coverage > 0:
        from ..degradations import _blobs

        hole |= _blobs(rng, (h, w), s.blob_coverage)
    hole |= rng.random((h, w)) < s.pixel_dropout
    # flying pixels at depth edges: a value between the two sides
    g = np.maximum(np.abs(np.diff(disp, axis=0, append=disp[-1:])), np.abs(np.diff(disp, axis=1, append=disp[:, -1:])))
    band = cv2.dilate((g > 4).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    flying = band & (rng.random((h, w)) < s.flying)
    zmin = cv2.erode(z.astype(np.float32), np.ones((3, 3), np.uint8))
    zmax = cv2.dilate(z.astype(np.float32), np.ones((3, 3), np.uint8))
    u = rng.random((h, w))
    z = np.where(flying, u * zmin + (1 - u) * zmax, z)
    imp = rng.random((h, w)) < s.impulses
    z = np.where(imp, rng.uniform(z.min(), z.max(), (h, w)), z)
    z = np.where(hole, 0.0, np.round(z))
    return np.clip(z, 0, 65535).astype(np.uint16)


def make_sequence(spec: SequenceSpec, frames: int = 30, height: int = 120, width: int = 160) -> dict:
    """The frames of ``spec``: ``depth`` (T,1,H,W) uint16 mm (the sensor), ``gt`` (T,1,H,W) float32 mm, ``rgb``
    (T,3,H,W) float32 in [0,1], ``moving`` (T,1,H,W) bool (pixels of a mover), ``hold_from`` (the first frame from
    which the camera holds still), ``name``.

    Examples:
        >>> s = make_sequence(STREAM_SEQUENCES[0], frames=3, height=32, width=40)
        >>> s["depth"].dtype, tuple(s["gt"].shape), s["hold_from"]
        (dtype('uint16'), (3, 1, 32, 40), 0)
    """
    if frames < 1 or height < 16 or width < 16:
        raise DepthSRError(f"make_sequence needs frames >= 1 and a frame of at least 16x16; got {frames} frames "
                           f"of {height}x{width}")
    pan = spec.camera == "pan"
    my, mx = (abs(spec.pan_speed[0]) * spec.pan_frames, abs(spec.pan_speed[1]) * spec.pan_frames) if pan else (0, 0)
    world = make_scene(height + my, width + mx, seed=spec.seed)
    wd = world["gt"][0].numpy()
    wrgb = world["rgb"].numpy().transpose(1, 2, 0)
    rng = np.random.default_rng([spec.seed, 7919])
    movers = [_mover(rng, height, width, spec.speed) for _ in range(spec.movers)]
    movers.sort(key=lambda m: m["disp"])  # far first
    out = {k: [] for k in ("depth", "gt", "rgb", "moving")}
    for t in range(frames):
        k = min(t, spec.pan_frames) if pan else 0
        oy, ox = k * abs(spec.pan_speed[0]), k * abs(spec.pan_speed[1])
        disp = wd[oy:oy + height, ox:ox + width].copy()
        rgb = wrgb[oy:oy + height, ox:ox + width].copy()
        moving = np.zeros((height, width), bool)
        for m in movers:
            _draw_mover(m, *_mover_at(m, t, height, width), disp, rgb, moving)
        frng = np.random.default_rng([spec.seed, t, 104729])
        out["depth"].append(_sensor(disp, rgb, spec.sensor, frng))
        out["gt"].append((DEPTH_CONSTANT / disp).astype(np.float32))
        out["rgb"].append(rgb.transpose(2, 0, 1).astype(np.float32))
        out["moving"].append(moving)
    return {"depth": np.stack(out["depth"])[:, None], "gt": np.stack(out["gt"])[:, None],
            "rgb": np.stack(out["rgb"]), "moving": np.stack(out["moving"])[:, None],
            "hold_from": min(spec.pan_frames, frames - 1) if pan else 0, "name": spec.name}
