"""A small synthetic face model (ellipsoid head with a nose) and synthetic targets for fit tests."""

from __future__ import annotations

import numpy as np
import trimesh

from albedo_model.model import MorphableModel
from albedo_model.params import MoMoCoefficients, RenderParameter, default_square, fit_to_image_size
from albedo_model.pca import PCAPart
from albedo_model.render.renderer import Renderer
from albedo_model.shading.image_formation import encode_gamma

RADII = np.array([75.0, 100.0, 90.0])

#: Landmark name -> unit direction on the sphere before the nose bump (+x = subject's left).
LANDMARK_DIRECTIONS = {
    "left.eye.corner_outer": (0.45, 0.25, 0.86), "left.eye.corner_inner": (0.15, 0.25, 0.96),
    "right.eye.corner_outer": (-0.45, 0.25, 0.86), "right.eye.corner_inner": (-0.15, 0.25, 0.96),
    "left.lips.corner": (0.25, -0.42, 0.87), "right.lips.corner": (-0.25, -0.42, 0.87),
    "center.lips.upper.outer": (0.0, -0.35, 0.94), "center.chin.tip": (0.0, -0.75, 0.66),
    "left.eyebrow.bend.upper": (0.35, 0.45, 0.82), "right.eyebrow.bend.upper": (-0.35, 0.45, 0.82),
    "left.ear.tragus.tip": (0.99, 0.0, 0.1), "right.ear.tragus.tip": (-0.99, 0.0, 0.1),
    "center.back.of.head": (0.0, 0.1, -0.99),
}


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def small_face_model(subdivisions: int = 4, seed: int = 0, *, specular: bool = True
                     ) -> MorphableModel:
    """Ellipsoid head (radii 75/100/90 mm) with a nose, 13 Basel-named landmarks, K=4/2/3 parts."""
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions)
    u = np.asarray(sphere.vertices, float)
    nose = np.exp(-np.sum((u - _unit([0.0, -0.05, 1.0])) ** 2, 1) / 0.02)
    v = u * RADII + u * 25.0 * nose[:, None]
    n = len(v)
    landmarks = {}
    for name, d in LANDMARK_DIRECTIONS.items():
        i = int(np.argmin(np.sum((u - _unit(d)) ** 2, 1)))
        landmarks[name] = v[i].copy()
    landmarks["center.nose.tip"] = v[int(np.argmax(v[:, 2]))].copy()
    rng = np.random.default_rng(seed)

    def smooth_part(mean, k, rms, noise=0.0):
        freqs = rng.normal(0, 1.5, (k, 3, 3))
        cols = [np.sin(u @ f + rng.uniform(0, np.pi, 3)).reshape(-1) for f in freqs]
        q, _ = np.linalg.qr(np.stack(cols, 1))
        return PCAPart(np.asarray(mean, float).reshape(-1), q, np.full(k, rms ** 2 * n), noise)

    skin = np.array([0.45, 0.28, 0.22]) * (1.0 + 0.1 * u[:, 1:2])
    return MorphableModel(
        v, np.asarray(sphere.faces), smooth_part(v, 4, 3.0),
        smooth_part(skin, 3, 0.03), expression=smooth_part(np.zeros_like(v), 2, 1.5),
        specular=smooth_part(np.full_like(v, 0.08), 3, 0.01) if specular else None,
        landmarks=landmarks, metadata={"synthetic": "true"},
    )


def scene(width: int = 64, height: int = 64, *, yaw: float = 0.0, pitch: float = 0.0,
          roll: float = 0.0, translation=(0.0, 0.0, -1000.0), coefficients=None,
          focal: float | None = None) -> RenderParameter:
    """Default camera for the image size, a pose, and coefficients (zeros by default)."""
    p = fit_to_image_size(default_square(), width, height)
    momo = coefficients if coefficients is not None else MoMoCoefficients.zeros(4, 3, 2)
    # the default f = 7.5 frames the 200 mm head in ~75 % of a square image at 1 m
    cam = p.camera if focal is None else p.camera._replace(focal_length=float(focal))
    pose = p.pose._replace(yaw=yaw, pitch=pitch, roll=roll, translation=tuple(translation))
    return p._replace(camera=cam, pose=pose, momo=momo)


def synthetic_target(model: MorphableModel, params: RenderParameter, *, background=0.35,
                     specular: bool = False):
    """Gamma-encoded image (H, W, 3) float64 and the visible projected landmarks {name: (2,)}."""
    r = Renderer(model, specular=specular, threads=1)
    out = r.render(params)
    img = np.asarray(encode_gamma(np.clip(out.image, 0.0, 1.0)), np.float64)
    img = np.where(out.mask[..., None], img, background)
    names, px, vis = r.landmarks(out.state)
    return img, {n: q for n, q, ok in zip(names, px, vis) if ok}


def random_lit_face(model: MorphableModel, rng: np.random.Generator, size: int, *,
                    yaw: float, pitch: float, noise: float = 0.01):
    """A random face (4 shape, 3 albedo, 2 expression coefficients) under a perturbed frontal SH light.

    Returns ``(truth, image, clicked)``: the scene, its diffuse render with
    Gaussian noise of sd ``noise`` (gamma-encoded, clipped) and the visible
    projected landmarks.
    """
    from albedo_model.params import SHLight

    truth = scene(size, size, yaw=yaw, pitch=pitch, coefficients=MoMoCoefficients(
        rng.normal(size=4), rng.normal(size=3), rng.normal(0, 0.7, 2)))
    truth = truth._replace(environment_map=SHLight(SHLight.frontal().coefficients
                                                   + rng.normal(0, 0.03, (9, 3))))
    image, clicked = synthetic_target(model, truth, specular=False)
    return truth, np.clip(image + rng.normal(0, noise, image.shape), 0, 1), clicked
