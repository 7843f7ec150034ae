"""Synthetic fitting cases with known truth: a random face of a model over a textured background.

:func:`synthetic_case` draws model coefficients, a pose, an SH light (and
optionally harder conditions: very dark skin, a saturated specular
highlight, a tiny face, a strong side light), renders the face with the
renderer the fitter uses (linear shading, specular, clamp), encodes it with the
pure 2.2 gamma, composites it over a noisy textured background, adds sensor
noise and quantises to 8 bits. It returns the image, the visible LFW
landmarks of the true instance and the true per-vertex albedo, so that fits
can be scored against the truth. Everything is drawn from one seed.

This module imports :mod:`albedo_model`, :mod:`pipeline.synthetic.head.landmarks`
and :mod:`mcmcfit.outputs.posterior`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from albedo_model.camera import pixel_scale
from albedo_model.errors import InputError
from albedo_model.model import MorphableModel
from albedo_model.params import (
    SH_N0,
    SH_N1,
    MoMoCoefficients,
    RenderParameter,
    SHLight,
    default_square,
    fit_to_image_size,
)
from albedo_model.render.renderer import Renderer
from albedo_model.shading.image_formation import GAMMA
from mcmcfit.outputs.posterior import visible_vertices
from pipeline.synthetic.head.landmarks import LFW_TLMS_NAMES

__all__ = ["DARK_SKIN_ALBEDO", "SyntheticCase", "synthetic_case"]

#: Linear sRGB diffuse albedo of very dark skin (Fitzpatrick VI, roughly: the
#: "African" PMC patch and Jacques' 18-43 % melanin range put it near these values).
DARK_SKIN_ALBEDO = (0.055, 0.032, 0.022)

_BACKGROUND_KINDS = ("textured", "flat")


class SyntheticCase(NamedTuple):
    """A synthetic photograph with its ground truth.

    Attributes
    ----------
    image : (H, W, 3) float64
        Gamma-encoded sRGB in [0, 1], quantised to 8 bits (value/255), as read
        from a PNG.
    landmarks : dict name -> (2,) float64
        Pixel positions (x right, y down) of the LFW landmarks visible in the true view.
    truth : RenderParameter
        The scene that was rendered (its ``momo`` holds every model coefficient).
    diffuse : (n, 3) float64
        True per-vertex diffuse albedo, linear sRGB.
    specular : (n, 3) float64 or None
        True per-vertex specular albedo (None when the model has none or
        ``specular=False``).
    visible : (n,) bool
        Vertices seen in the true view.
    """

    image: np.ndarray
    landmarks: dict
    truth: RenderParameter
    diffuse: np.ndarray
    specular: np.ndarray | None
    visible: np.ndarray


def _sh_light(rng: np.random.Generator, *, side: bool, scale: float) -> SHLight:
    """Ambient + one directional lobe (bands 0-1) + small band-2 terms, slightly tinted.

    With the Lambert factors built into the shader, a normal n is lit with about
    ``ambient + diffuse (n . d)`` (times the tint) plus the band-2 wiggle.
    """
    if side:
        ambient, diffuse = rng.uniform(0.15, 0.25), rng.uniform(0.9, 1.1)
        sx = rng.choice([-1.0, 1.0])
        d = np.array([sx * 0.95, rng.uniform(0.0, 0.2), 0.25])
    else:
        ambient, diffuse = rng.uniform(0.6, 0.85), rng.uniform(0.25, 0.5)
        az, el = rng.uniform(-0.6, 0.6), rng.uniform(-0.1, 0.5)
        d = np.array([math.sin(az) * math.cos(el), math.sin(el), math.cos(az) * math.cos(el)])
    d /= np.linalg.norm(d)
    tint = 1.0 + rng.normal(0.0, 0.04, 3)
    c = np.zeros((9, 3))
    c[0] = ambient / (math.pi * SH_N0)
    a1 = 2.0 * math.pi / 3.0 * SH_N1
    c[1], c[2], c[3] = diffuse * d[1] / a1, diffuse * d[2] / a1, diffuse * d[0] / a1
    c[4:] = rng.normal(0.0, 0.03, (5, 1))
    return SHLight(c * tint[None, :] * scale)


def _skin_coefficients(model: MorphableModel, target: np.ndarray, rank: int) -> np.ndarray:
    """Albedo coefficients (first ``rank``) whose instance is closest to ``target`` per vertex."""
    part = model.diffuse
    w = part.scaled_basis[:, :rank].astype(np.float64)
    resid = np.asarray(target, np.float64).reshape(-1) - part.mean.astype(np.float64)
    # small ridge: stay near the prior where the data do not need a component
    return np.linalg.solve(w.T @ w + 1e-3 * np.eye(rank), w.T @ resid)


#: A drawn face is redrawn when more than this fraction of its vertices has a
#: diffuse channel below :data:`_MIN_ALBEDO` or above 1 (a linear Gaussian albedo
#: model spanning Fitzpatrick I-VI puts about one draw in six below type VI).
_MAX_OUT_OF_GAMUT = 0.05
_MIN_ALBEDO = 0.005


def _physical_albedo(model: MorphableModel, albedo: np.ndarray, k: int, seed: int,
                    tries: int = 100) -> np.ndarray:
    """``albedo``, or a redraw of its first ``k`` entries whose diffuse albedo is physical.

    Redraws come from their own generator (``[seed, 1, attempt]``), so the other
    draws of a case (pose, light, ...) do not depend on whether a redraw happened.
    """
    for attempt in range(tries + 1):
        d = model.diffuse_instance(albedo).reshape(-1, 3)
        bad = (d.min(axis=1) < _MIN_ALBEDO) | (d.max(axis=1) > 1.0)
        if bad.mean() <= _MAX_OUT_OF_GAMUT:
            return albedo
        albedo = albedo.copy()
        albedo[:k] = np.random.default_rng([seed, 1, attempt]).normal(0.0, 1.0, k)
    raise InputError(f"no physical diffuse albedo in {tries} draws of the model")


def _background(rng: np.random.Generator, h: int, w: int, kind: str) -> np.ndarray:
    """Gamma-encoded background: smooth coloured blobs, stripes and fine noise in [0, 1]."""
    if kind == "flat":
        return np.broadcast_to(rng.uniform(0.2, 0.8, 3), (h, w, 3)).copy()
    y, x = np.mgrid[0:h, 0:w] / max(h, w)
    img = np.broadcast_to(rng.uniform(0.2, 0.7, 3), (h, w, 3)).copy()
    for _ in range(6):
        f = rng.uniform(1.0, 8.0, 2) * rng.choice([-1.0, 1.0], 2)
        phase = rng.uniform(0, 2 * math.pi)
        wave = np.sin(2 * math.pi * (f[0] * x + f[1] * y) + phase)
        img += 0.12 * wave[..., None] * rng.normal(0.0, 1.0, 3)
    img += rng.normal(0.0, 0.04, img.shape)
    return np.clip(img, 0.0, 1.0)


def synthetic_case(model: MorphableModel, *, seed: int = 0, size: int = 250,
                   yaw_deg: float | None = None, skin: str | None = None, specular: bool = True,
                   face_width_px: float | None = None, side_light: bool = False,
                   background: str = "textured", highlight: bool = False,
                   n_coefficients: int = 10, noise: float = 0.01) -> SyntheticCase:
    """Render a random face of ``model`` with known truth.

    Parameters
    ----------
    model : MorphableModel
    seed : int
        Every random choice derives from it (same seed, same case).
    size : int
        Width and height of the image in pixels.
    yaw_deg : float, optional
        Head yaw in degrees; default uniform in [-30, 30].
    skin : {None, "dark"}
        ``"dark"`` replaces the random albedo coefficients by those closest to
        :data:`DARK_SKIN_ALBEDO` (very dark skin, Fitzpatrick VI).
    specular : bool
        Render the specular term (when the model has specular albedo).
    face_width_px : float, optional
        Distance chosen so that the model's reference width spans this many
        pixels (e.g. 24 for a tiny face); default: 1.1-1.25 m away with the default
        camera (about 120-140 px wide at 250²).
    side_light : bool
        A strong light from the side (ambient ~0.2, directional ~1.0 at ~75° off the view).
    background : {"textured", "flat"}
        Noisy textured background (default) or one flat random colour.
    highlight : bool
        A bright light and a low specular exponent: the specular highlight saturates.
    n_coefficients : int
        Leading shape and colour coefficients drawn from N(0, 1) (others stay 0;
        expression: all of the model's, at most 5, from N(0, 1)).
    noise : float
        Standard deviation of the Gaussian sensor noise added to the
        gamma-encoded image before 8-bit quantisation.

    Returns
    -------
    SyntheticCase

    Raises
    ------
    InputError
        Unknown ``skin`` or ``background``, or a size below 16 pixels.
    """
    if skin not in (None, "dark"):
        raise InputError(f"skin must be None or 'dark', got {skin!r}")
    if background not in _BACKGROUND_KINDS:
        raise InputError(f"background must be one of {_BACKGROUND_KINDS}, got {background!r}")
    if int(size) < 16:
        raise InputError(f"image size must be >= 16 pixels, got {size}")
    size = int(size)
    rng = np.random.default_rng(seed)
    ranks = model.ranks
    k_shape = min(n_coefficients, ranks["shape"])
    k_albedo = min(n_coefficients, ranks["diffuse"])
    k_expr = min(5, ranks.get("expression", 0))
    shape = np.zeros(ranks["shape"])
    shape[:k_shape] = rng.normal(0.0, 1.0, k_shape)
    albedo = np.zeros(ranks["diffuse"])
    albedo[:k_albedo] = rng.normal(0.0, 1.0, k_albedo)
    albedo = _physical_albedo(model, albedo, k_albedo, seed)
    expression = np.zeros(ranks.get("expression", 0))
    expression[:k_expr] = rng.normal(0.0, 0.7, k_expr)
    if skin == "dark":
        target = np.broadcast_to(np.asarray(DARK_SKIN_ALBEDO), (model.n_vertices, 3))
        rel = model.diffuse.mean.reshape(-1, 3) / model.diffuse.mean.reshape(-1, 3).mean(0)
        albedo = np.zeros(ranks["diffuse"])
        albedo[:] = _skin_coefficients(model, target * rel, ranks["diffuse"])

    yaw = math.radians(rng.uniform(-30.0, 30.0) if yaw_deg is None else float(yaw_deg))
    pitch = math.radians(rng.uniform(-10.0, 10.0))
    roll = math.radians(rng.uniform(-5.0, 5.0))
    params = fit_to_image_size(default_square(), size, size)
    fx, _ = pixel_scale(params.camera, params.image_size)
    if face_width_px is None:
        distance = 1000.0 * rng.uniform(1.1, 1.25)
    else:
        width_mm = float(np.ptp(model.vertices[:, 0]))
        distance = fx * width_mm / float(face_width_px)
    # keep the face inside the image: offsets up to 8 % of the visible width
    half_mm = 0.5 * size / fx * distance
    tx, ty = rng.uniform(-0.08, 0.08, 2) * half_mm
    pose = params.pose._replace(yaw=yaw, pitch=pitch, roll=roll,
                                translation=(float(tx), float(ty), -float(distance)))
    light = _sh_light(rng, side=side_light, scale=2.5 if highlight else 1.0)
    exponent = 8.0 if highlight else float(rng.uniform(15.0, 30.0))
    truth = params._replace(
        pose=pose, environment_map=light, specular_exponent=exponent,
        momo=MoMoCoefficients(shape, albedo, expression, ""))

    renderer = Renderer(model, specular=specular, threads=1)
    state = renderer.init_state(truth)
    rendered = renderer.image(state)
    face = np.clip(np.asarray(rendered.image, np.float64), 0.0, 1.0)
    face = np.where(face > 0.0, np.exp(np.log(np.maximum(face, 1e-300)) / GAMMA), 0.0)
    bg = _background(rng, size, size, background)
    img = np.where(rendered.mask[..., None], face, bg)
    img = img + rng.normal(0.0, float(noise), img.shape)
    img = np.round(np.clip(img, 0.0, 1.0) * 255.0) / 255.0

    names, px, vis = renderer.landmarks(state, [n for n in LFW_TLMS_NAMES
                                                 if n in model.landmark_vertices])
    inside = (px[:, 0] >= 0) & (px[:, 0] < size) & (px[:, 1] >= 0) & (px[:, 1] < size)
    landmarks = {n: np.asarray(p, np.float64) for n, p, ok, ins in zip(names, px, vis, inside)
                 if ok and ins}
    diffuse = model.diffuse_instance(albedo)
    spec = model.specular_instance(albedo) if renderer.specular else None
    return SyntheticCase(img, landmarks, truth, diffuse, spec, visible_vertices(renderer, state))
