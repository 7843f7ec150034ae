"""Model, scenes and reference image of the renderer tests (test_renderer, test_renderer_steps).

A small bumpy-sphere morphable model, a scene that sees it, an independent
NumPy z-buffer image of it, and one parameter move per block.

This module imports :mod:`albedo_model.model`, :mod:`albedo_model.params`,
:mod:`albedo_model.pca`, :mod:`albedo_model.sh` and :mod:`albedo_model.camera`
(and the test helper ``zbuffer_reference``).
"""

from __future__ import annotations

import numpy as np
import trimesh
from zbuffer_reference import render_zbuffer

from albedo_model.model import MorphableModel, vertex_normals
from albedo_model.params import (
    Block, Camera, ColorTransform, ImageSize, MoMoCoefficients, Pose, SHLight, default_square,
)
from albedo_model.pca import PCAPart
from albedo_model.sh import sh_irradiance


def bumpy_model(seed=0, k=4):
    """Return a bumpy-sphere morphable model with ``k`` random components per part."""
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=60.0)
    v = np.asarray(mesh.vertices)
    v = v * (1.0 + 0.08 * np.sin(3 * v[:, :1] / 60.0) * np.cos(2 * v[:, 1:2] / 60.0))
    rng = np.random.default_rng(seed)
    n3 = 3 * len(v)

    def part(mean, scale):
        q, _ = np.linalg.qr(rng.standard_normal((n3, k)))
        return PCAPart(mean, q, np.full(k, scale))

    colour = 0.5 + 0.3 * np.sin(v / 17.0)
    return MorphableModel(v, np.asarray(mesh.faces), part(v.ravel(), 400.0),
                          part(colour.ravel(), 0.5), specular=part(np.full(n3, 0.3), 0.2))


def scene(size=(64, 48), yaw=0.3, pitch=-0.2, sh=None, pp=(0.05, -0.1)):
    """Return render parameters that see :func:`bumpy_model` from about 700 mm."""
    p = default_square()
    sh = SHLight.ambient_white() if sh is None else sh
    return p._replace(
        pose=Pose(1.0, (4.0, -3.0, -700.0), 0.1, yaw, pitch),
        camera=Camera(focal_length=7.5, sensor_size=(2.0, 2.0 * size[1] / size[0]),
                      principal_point=pp),
        image_size=ImageSize(*size), environment_map=sh,
        momo=MoMoCoefficients(np.array([0.3, -0.2]), np.array([0.5, 0.1, -0.4]), np.zeros(0)),
    )


def zbuffer_image(model, params, sh_coeffs):
    """Independent reference: numpy z-buffer + barycentric interpolation + numpy SH."""
    verts = model.shape_instance(params.momo.shape)
    albedo = model.diffuse_instance(params.momo.albedo)
    normals = vertex_normals(verts, model.triangles)
    prim, bary, _ = render_zbuffer(verts, model.triangles, params.pose, params.view, params.camera,
                                params.image_size)
    hit = prim >= 0
    tri = model.triangles[np.maximum(prim, 0)]
    w = np.stack([1 - bary[..., 0] - bary[..., 1], bary[..., 0], bary[..., 1]], -1)
    interp = lambda a: np.einsum("hwk,hwkc->hwc", w, a[tri])  # noqa: E731
    from albedo_model.camera import euler_rotation
    r = euler_rotation(params.pose.roll, params.pose.yaw, params.pose.pitch)
    n = interp(normals) @ r.T
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    img = interp(albedo) * sh_irradiance(sh_coeffs, n)
    return np.where(hit[..., None], np.clip(img, 0, 1), 0.0), hit


def moves(params, rng):
    """One changed parameter set per block, as a proposal would make."""
    m = params.momo
    yield Block.POSE, params._replace(pose=params.pose._replace(yaw=params.pose.yaw + 0.2))
    yield Block.CAMERA, params._replace(camera=params.camera._replace(focal_length=8.0))
    yield Block.SHAPE, params._replace(momo=m._replace(shape=m.shape + rng.normal(0, 1, 2)))
    yield Block.ALBEDO, params._replace(momo=m._replace(albedo=m.albedo + rng.normal(0, 1, 3)))
    sh = params.environment_map.coefficients * 0.7
    yield Block.LIGHT, params._replace(environment_map=SHLight(sh))
    yield Block.COLOR_TRANSFORM, params._replace(
        color_transform=ColorTransform((1.1, 0.9, 1.0), 0.8, (0.01, 0, 0)))
