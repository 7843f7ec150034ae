"""Photographs of a held-out subject in a scene: the renderer's effects plus a camera.

:func:`render_scene` poses a head with a subject's true albedo maps (any
per-vertex maps, not a model instance: a one-instance "truth model" on the
same mesh), lights it as its :class:`~pipeline.synthetic.scenes.SceneSpec`
says, renders it with the project's renderer (SH light, specular; the
scalismo directional light and its cast shadows by Embree occlusion rays only
when the scene has them) and passes the linear image through a camera: a
white-balance matrix, shot and read noise, the pure 2.2 gamma, a textured
background, 8-bit quantisation and JPEG, each only when the scene asks for it.
It returns the encoded photograph (JPEG bytes or a PNG-ready array), noisy
landmarks, the true scene, the vertices visible in the true view, and the
seconds each stage took with the list of effects computed.

This module imports :mod:`albedo_model` (params, PCA, model, renderer) and
:mod:`pipeline.synthetic.head.landmarks`; Pillow is imported for JPEG.
"""

from __future__ import annotations

import dataclasses
import io
import math
import time
from typing import NamedTuple

import numpy as np

from albedo_model.camera import pixel_scale
from albedo_model.errors import InputError
from albedo_model.model import MorphableModel
from albedo_model.params import (
    SH_N0,
    SH_N1,
    DirectionalLight,
    MoMoCoefficients,
    RenderParameter,
    SHLight,
    default_square,
    fit_to_image_size,
)
from albedo_model.pca import PCAPart
from pipeline.synthetic.head.landmarks import LFW_TLMS_NAMES
from pipeline.synthetic.scenes import SceneSpec

__all__ = ["ScenePhoto", "render_scene", "truth_model"]

_GAMMA = 2.2


class ScenePhoto(NamedTuple):
    """A rendered photograph and its truth.

    Attributes
    ----------
    image : (H, W, 3) float64
        The photograph as a reader decodes it: gamma-encoded sRGB in [0, 1].
    encoded : bytes
        The file's bytes (JPEG when the scene asks for it, else PNG).
    suffix : str
        ``".jpg"`` or ``".png"``.
    landmarks : dict of str to (2,) float
        Noisy pixel positions of the LFW landmarks visible in the true view.
    truth : RenderParameter
        The rendered scene (shape coefficients in ``momo``; the albedo is the maps').
    visible : (n,) bool
        Vertices seen in the true view.
    colour_matrix : (3, 3) float
        The white-balance matrix applied (identity when off).
    computed : list of str
        The effects computed (e.g. ``["specular", "shadow rays", "JPEG"]``).
    timings : dict of str to float
        Seconds per stage: ``render_s``, ``camera_s``, ``encode_s``; and
        ``shadow_rays``, the occlusion rays cast (0 unless the scene has shadows).
    """

    image: np.ndarray
    encoded: bytes
    suffix: str
    landmarks: dict
    truth: RenderParameter
    visible: np.ndarray
    colour_matrix: np.ndarray
    computed: list
    timings: dict


def truth_model(model: MorphableModel, diffuse: np.ndarray,
                specular: np.ndarray | None) -> MorphableModel:
    """Return ``model`` with albedo parts whose only instance is the given maps.

    The geometry (shape, expression, landmarks) is ``model``'s; each colour
    part has mean = the map and one zero component (rank 1), so rendering it
    with any albedo coefficients gives exactly the maps.
    """
    d = np.asarray(diffuse, np.float32).reshape(-1)

    def part(mean):
        return PCAPart(mean, np.zeros((mean.size, 1), np.float32), np.ones(1, np.float32))

    spec = None if specular is None else part(np.asarray(specular, np.float32).reshape(-1))
    return dataclasses.replace(model, diffuse=part(d), specular=spec, shared_albedo=True)


def _sh(ambient: float, lobe: float, direction: np.ndarray, rng: np.random.Generator) -> SHLight:
    """SH light ``ambient + lobe (n . d)`` (bands 0-1) with small band-2 terms and a tint."""
    c = np.zeros((9, 3))
    c[0] = ambient / (math.pi * SH_N0)
    a1 = 2.0 * math.pi / 3.0 * SH_N1
    c[1], c[2], c[3] = lobe * direction[1] / a1, lobe * direction[2] / a1, lobe * direction[0] / a1
    c[4:] = rng.normal(0.0, 0.02, (5, 1))
    return SHLight(c * (1.0 + rng.normal(0.0, 0.03, 3))[None, :])


def _unit(v) -> np.ndarray:
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v)


def _scene_params(model: MorphableModel, spec: SceneSpec, rng: np.random.Generator,
                  size: int, identity: np.ndarray | None = None) -> RenderParameter:
    ranks = model.ranks
    shape = np.zeros(ranks["shape"])
    shape[: min(10, ranks["shape"])] = rng.normal(0.0, 1.0, min(10, ranks["shape"]))
    if identity is not None:  # drawn anyway: the rest of the scene is the seed's as before
        shape = np.asarray(identity, np.float64).copy()
    expression = np.zeros(ranks.get("expression", 0))
    expression[: min(3, expression.size)] = rng.normal(0.0, 0.5, min(3, expression.size))
    lo, hi = spec.yaw_deg
    yaw = math.radians(rng.uniform(lo, hi) * rng.choice([-1.0, 1.0]))
    params = fit_to_image_size(default_square(), size, size)
    fx, _ = pixel_scale(params.camera, params.image_size)
    distance = 1000.0 * rng.uniform(1.1, 1.25)
    tx, ty = rng.uniform(-0.06, 0.06, 2) * 0.5 * size / fx * distance
    pose = params.pose._replace(yaw=yaw, pitch=math.radians(rng.uniform(-8, 8)),
                                roll=math.radians(rng.uniform(-4, 4)),
                                translation=(float(tx), float(ty), -float(distance)))
    az, el = rng.uniform(-0.6, 0.6), rng.uniform(0.0, 0.5)
    lobe_dir = _unit([math.sin(az) * math.cos(el), math.sin(el), math.cos(az) * math.cos(el)])
    light = _sh(spec.ambient, spec.sh_directional, lobe_dir, rng)
    directional = DirectionalLight()
    if spec.directional > 0:
        a = math.radians(spec.directional_azimuth_deg) * rng.choice([-1.0, 1.0])
        d = _unit([math.sin(a), rng.uniform(0.1, 0.4), math.cos(a)])
        k = spec.directional
        directional = DirectionalLight(diffuse=(k, k, k), direction=tuple(d),
                                       specular=(0.4 * k,) * 3, shininess=20.0)
    albedo = np.zeros(1)
    return params._replace(pose=pose, environment_map=light, directional_light=directional,
                           specular_exponent=float(rng.uniform(15.0, 30.0)),
                           momo=MoMoCoefficients(shape, albedo, expression, ""))


def _background(rng: np.random.Generator, size: int, kind: str) -> np.ndarray:
    """Return an encoded background: a flat colour, or coloured waves and fine noise."""
    base = np.broadcast_to(rng.uniform(0.2, 0.7, 3), (size, size, 3)).copy()
    if kind == "flat":
        return base
    y, x = np.mgrid[0:size, 0:size] / size
    for _ in range(6):
        f = rng.uniform(1.0, 8.0, 2) * rng.choice([-1.0, 1.0], 2)
        wave = np.sin(2 * math.pi * (f[0] * x + f[1] * y) + rng.uniform(0, 2 * math.pi))
        base += 0.12 * wave[..., None] * rng.normal(0.0, 1.0, 3)
    return np.clip(base + rng.normal(0.0, 0.04, base.shape), 0.0, 1.0)


def _camera(linear: np.ndarray, mask: np.ndarray, spec: SceneSpec, rng: np.random.Generator,
            size: int, computed: list) -> tuple[np.ndarray, np.ndarray]:
    """Linear face image -> encoded photograph in [0, 1] (before 8-bit and JPEG)."""
    img = np.asarray(linear, np.float64)
    matrix = np.eye(3)
    if spec.white_balance_sd > 0:
        matrix = matrix + rng.normal(0.0, spec.white_balance_sd, (3, 3))
        img = img @ matrix.T
        computed.append("white balance")
    img = np.clip(img, 0.0, None)
    noise_var = np.full(img.shape, spec.read_noise ** 2)
    if spec.shot_noise > 0:
        noise_var = noise_var + spec.shot_noise * img
        computed.append("shot noise")
    if spec.read_noise > 0 or spec.shot_noise > 0:
        img = img + rng.standard_normal(img.shape) * np.sqrt(noise_var)
    face = np.clip(img, 0.0, 1.0) ** (1.0 / _GAMMA)
    bg = _background(rng, size, spec.background)
    return np.where(mask[..., None], face, bg), matrix


def _encode(image: np.ndarray, quality: int | None) -> tuple[bytes, str, np.ndarray]:
    from PIL import Image

    u8 = np.round(np.clip(image, 0.0, 1.0) * 255.0).astype(np.uint8)
    buf = io.BytesIO()
    if quality is None:
        Image.fromarray(u8).save(buf, format="PNG")
        return buf.getvalue(), ".png", u8 / 255.0
    Image.fromarray(u8).save(buf, format="JPEG", quality=int(quality))
    data = buf.getvalue()
    with Image.open(io.BytesIO(data)) as im:
        decoded = np.asarray(im.convert("RGB"), np.float64) / 255.0
    return data, ".jpg", decoded


def render_scene(model: MorphableModel, diffuse: np.ndarray, specular: np.ndarray,
                 spec: SceneSpec, *, seed, size: int = 250,
                 shape: np.ndarray | None = None) -> ScenePhoto:
    """Photograph a head with albedo maps ``diffuse``/``specular`` in scene ``spec``.

    Parameters
    ----------
    model : MorphableModel
        Supplies the geometry (shape and expression parts, landmarks).
    diffuse, specular : (n, 3) float arrays, linear sRGB
        The subject's true albedo.
    spec : SceneSpec
    seed : int or sequence of int
        Every random choice (pose, light, camera, noise, landmarks) derives from it.
    size : int
        Image width and height.
    shape : (k,) float array, optional
        The head's shape coefficients (default: drawn from ``seed``, 10 leading
        ones from N(0, 1)); give the same to photograph one person in several scenes.

    Returns
    -------
    ScenePhoto
    """
    from albedo_model.render.renderer import Renderer

    rng = np.random.default_rng(seed)
    size = int(size)
    if shape is not None and np.shape(shape) != (model.ranks["shape"],):
        raise InputError(f"shape must hold the model's {model.ranks['shape']} coefficients, "
                         f"got shape {np.shape(shape)}")
    truth = _scene_params(model, spec, rng, size, shape)
    tm = truth_model(model, diffuse, specular if spec.specular else None)
    shadows = bool(spec.shadows and spec.directional > 0)
    renderer = Renderer(tm, specular=spec.specular, shadows=shadows, threads=1,
                        directional_specular_map=spec.directional > 0)
    computed = []
    effects = renderer.effects(truth)
    computed += [name for name, on in (("specular", effects.specular),
                                       ("directional light", effects.directional),
                                       ("shadow rays", effects.shadows)) if on]
    t0 = time.perf_counter()
    state = renderer.init_state(truth)
    rendered = renderer.image(state)
    t1 = time.perf_counter()
    photo, matrix = _camera(rendered.image, rendered.mask, spec, rng, size, computed)
    t2 = time.perf_counter()
    encoded, suffix, decoded = _encode(photo, spec.jpeg_quality)
    if spec.jpeg_quality is not None:
        computed.append("JPEG")
    t3 = time.perf_counter()
    names, px, vis = renderer.landmarks(state, [n for n in LFW_TLMS_NAMES
                                                if n in model.landmark_vertices])
    sd = spec.landmark_noise_px * size / 250.0
    noisy = np.asarray(px, np.float64) + rng.normal(0.0, sd, np.shape(px))
    inside = np.all((noisy >= 0) & (noisy < size), axis=1)
    landmarks = {n: p for n, p, ok, ins in zip(names, noisy, vis, inside) if ok and ins}
    hit = state.hits.prim_id
    visible = np.zeros(model.n_vertices, bool)
    visible[np.unique(np.asarray(model.triangles)[hit[hit >= 0]])] = True
    shadow_rays = int(np.sum(hit >= 0)) if effects.shadows else 0  # one per face pixel
    return ScenePhoto(decoded, encoded, suffix, landmarks, truth, visible, matrix, computed,
                      {"render_s": t1 - t0, "camera_s": t2 - t1, "encode_s": t3 - t2,
                       "shadow_rays": shadow_rays})
