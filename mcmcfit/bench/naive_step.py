"""The naive sampler step the renderer's caching is measured against.

Everything is recomputed from the parameters on every step, the obvious way:
the full model instance with all coefficients (NumPy), a new Embree scene,
the camera rays, vertex normals in NumPy, and the unspecialised
:func:`albedo_model.shading.naive.shade_naive` on host arrays (copied to the
device on each call), followed by the same likelihood as the fast path.

This module imports only :mod:`albedo_model` (camera, model, params, render.raycast,
shading.image_formation, shading.naive).
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import numpy as np

from albedo_model.camera import _eye_rays, camera_rays, euler_rotation, eye_from_world
from albedo_model.model import MorphableModel, vertex_normals
from albedo_model.params import RenderParameter
from albedo_model.render.raycast import RayCaster
from albedo_model.shading.image_formation import Effects, shading_params
from albedo_model.shading.naive import shade_naive

__all__ = ["NaiveStep"]


class NaiveStep:
    """Evaluate ``likelihood(rgb, mask, *args)`` for parameters, caching nothing.

    Parameters
    ----------
    model : MorphableModel
    effects : Effects
        The effect switches (the naive shader computes every effect regardless).
    likelihood : callable
        Jitted ``likelihood(rgb, mask, *args) -> scalar`` on device arrays.
    threads : int
        Ray-casting threads.
    """

    def __init__(self, model: MorphableModel, effects: Effects,
                 likelihood: Callable, threads: int = 1):
        self.model = model
        self.effects = effects
        self.likelihood = likelihood
        self.threads = threads
        self._triangles = np.asarray(model.triangles, np.int32)

    def __call__(self, params: RenderParameter, *args) -> float:
        """Log-likelihood of ``params`` (a host float), computed from scratch."""
        m, p = self.model, params
        shape = m.shape.instance(p.momo.shape)
        if m.expression is not None:
            shape = shape + m.expression.instance(p.momo.expression)
        vertices = shape.reshape(-1, 3)
        caster = RayCaster(vertices, self._triangles, threads=self.threads, update="rebuild")
        w, h = p.image_size
        origins, directions = camera_rays(p.camera, p.image_size, p.pose, p.view)
        hits = caster.cast(origins, directions, tfar=float(p.camera.far - p.camera.near),
                           image_shape=(h, w))
        normals = vertex_normals(vertices, self._triangles).astype(np.float32)
        diffuse = m.diffuse.instance(p.momo.albedo).reshape(-1, 3).astype(np.float32)
        specular = None
        if m.specular is not None:
            c = p.momo.albedo[: m.specular.rank] if m.shared_albedo else None
            specular = m.specular.instance(c).reshape(-1, 3).astype(np.float32)
        _, eye_dirs = _eye_rays(p.camera, p.image_size)
        r_view, _ = eye_from_world(p.view)
        ray_dirs = (eye_dirs[:, :3] @ r_view).astype(np.float32)
        rotation = euler_rotation(p.pose.roll, p.pose.yaw, p.pose.pitch)
        out = shade_naive(self.effects, self._triangles, normals, diffuse, specular,
                          hits.prim_id, hits.bary, ray_dirs, shading_params(p, rotation))
        return float(jax.block_until_ready(self.likelihood(out.rgb, out.mask, *args)))
