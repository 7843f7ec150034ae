"""A private ray cast at given parameters: every pixel's triangle, or some pixels', as fixed hits.

The samplers' renderer keeps the accepted scene; an optimiser or a gradient
that needs the triangles seen at *other* parameters casts into a scene of its
own (:class:`SceneCaster`, refitted in place), and :func:`hits_at` turns a
list of pixels with their triangles into the
:class:`~albedo_model.render.differentiable.FixedHits` the JAX colour
functions read, padded to a few distinct sizes.

This module imports :mod:`albedo_model.camera`, :mod:`albedo_model.params` and
:mod:`albedo_model.render` (differentiable, instances, raycast, visibility).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from albedo_model.camera import camera_rays, pixel_window
from albedo_model.params import RenderParameter
from albedo_model.render.differentiable import FixedHits
from albedo_model.render.instances import ModelInstances
from albedo_model.render.raycast import RayCaster
from albedo_model.render.visibility import directional_visibility

__all__ = ["PIXEL_BUCKET", "SceneCaster", "hits_at"]


class SceneCaster:
    """A private ray caster: the triangle and ray parameter each pixel sees at some parameters.

    Parameters
    ----------
    model : MorphableModel
    threads : int
    """

    def __init__(self, model, *, threads: int = 1):
        self.model = model
        self._threads = int(threads)
        self._caster: RayCaster | None = None
        self._rays: tuple[np.ndarray, np.ndarray] | None = None
        self._instances = ModelInstances(model, specular=False)

    def _scene(self, params: RenderParameter) -> None:
        """Move the private scene to ``params``' geometry."""
        # float32 from all coefficients (a function of ``params`` alone, no deltas)
        v32 = self._instances.shape(params).reshape(-1, 3)
        if self._caster is None:
            self._caster = RayCaster(v32, self.model.triangles, threads=self._threads)
        else:
            self._caster.update_vertices(v32)
        self._caster_vertices = v32.reshape(-1, 3)

    def _cast_rays(self, params: RenderParameter, pixels: np.ndarray):
        """Cast the rays of ``pixels`` only (their rays alone are formed) into the scene."""
        p = params
        o, d = camera_rays(p.camera, p.image_size, p.pose, p.view, pixels=pixels)
        return self._caster.cast(o, d, tfar=float(p.camera.far - p.camera.near))

    def cast_pixels(self, params: RenderParameter, pixels: np.ndarray) -> np.ndarray:
        """Return the triangle (-1: miss) seen by each of ``pixels`` (row-major) at ``params``.

        Only those rays are cast, without closing Embree's rare leaks between
        triangles (about one ray in 10^5 reports a miss on a closed surface).
        """
        self._scene(params)
        return np.asarray(self._cast_rays(params, pixels).prim_id)

    def shadow(self, params: RenderParameter, pixels: np.ndarray, *, rays: int = 1,
               spread_deg: float = 0.0) -> np.ndarray:
        """Return the directional light's visibility (1 lit, 0 shadowed) at ``pixels`` (row-major).

        The pixels' rays are cast for their surface points, then ``rays`` shadow
        rays from each over a light of angular radius ``spread_deg``
        (:func:`~albedo_model.render.visibility.directional_visibility`).
        """
        self._scene(params)
        hits = self._cast_rays(params, pixels)
        vertices = self._caster_vertices
        return directional_visibility(hits, vertices, self.model.triangles,
                                      params.pose, params.directional_light.direction,
                                      self._caster, rays=rays, spread_deg=spread_deg)

    def cast(self, params: RenderParameter) -> tuple[np.ndarray, np.ndarray]:
        """Return ``(prim_id (H W,) int32, t (H W,) float32)`` of a ray cast at ``params``."""
        p = params
        self._scene(p)
        w, h = int(p.image_size.width), int(p.image_size.height)
        if self._rays is None or len(self._rays[0]) != w * h:
            self._rays = (np.empty((w * h, 3), np.float32), np.empty((w * h, 3), np.float32))
        camera_rays(p.camera, p.image_size, p.pose, p.view, out=self._rays)
        window = pixel_window(self._caster.bounds, p.camera, p.image_size, p.pose, p.view)
        hits = self._caster.cast(*self._rays, tfar=float(p.camera.far - p.camera.near),
                                 image_shape=(h, w), window=window)
        return np.asarray(hits.prim_id), np.asarray(hits.t)


#: Pixel lists are padded to a multiple of this (few distinct shapes: few compilations).
PIXEL_BUCKET = 2048


def hits_at(prim_id: np.ndarray, pixels: np.ndarray, width: int,
            shadow: np.ndarray | None = None) -> FixedHits:
    """Return the :class:`FixedHits` of some pixels (row-major indices) of a ray cast.

    The list is padded with masked entries to a multiple of :data:`PIXEL_BUCKET`
    (their colours are the background and their derivatives zero). ``shadow``
    is the directional light's visibility at ``pixels`` (cast shadows), if any.
    """
    pixels = np.asarray(pixels, np.int64)
    n = pixels.size
    size = max(PIXEL_BUCKET, -(-n // PIXEL_BUCKET) * PIXEL_BUCKET)
    padded = np.zeros(size, np.int64)
    padded[:n] = pixels
    prim = np.asarray(prim_id)[padded]
    valid = np.arange(size) < n
    ys, xs = np.divmod(padded, int(width))
    vis = None
    if shadow is not None:
        vis = np.ones(size, np.float32)
        vis[:n] = np.asarray(shadow, np.float32)
        vis = jnp.asarray(vis)
    return FixedHits(padded.astype(np.int32), jnp.asarray(xs, jnp.float32),
                     jnp.asarray(ys, jnp.float32),
                     jnp.asarray(np.where(valid, np.maximum(prim, 0), 0), jnp.int32),
                     jnp.asarray(valid & (prim >= 0)), vis)
