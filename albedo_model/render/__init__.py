"""Forming an image of a model instance by ray casting, with caches driven by parameter blocks.

Modules
-------
cache_table
    The one stage -> blocks table: which parameter blocks each cached product
    reads, and the version stamps the caches are keyed on.
renderer
    :class:`Renderer`: the stages of a render, recomputed only where a move's
    blocks make them stale; :func:`render`, one uncached image.
state
    :class:`RenderState`, what a renderer caches per scene, and the per-pixel
    :class:`Deferred` caches.
stages
    The jitted stages (normals, pixel hits, geometry, albedo, light, image).
pixel_work
    The pixel set the per-pixel caches hold, what a likelihood fuses, view rays.
instances
    Shape and albedo instances (float32), updated by coefficient-block deltas.
albedo_updates
    The albedo instance on the device, updated by coefficient-block deltas.
raycast, ray_batches, embree_refit, scene_slots
    Embree ray casting (the only ``embreex`` importer), its NumPy side (ray
    buffers, hit records, windows, leak closing), in-place BVH refit, and the
    double-buffered scenes that make a rejected geometry move free.
normals
    Vertex normals on the device.
visibility
    Cast shadows of a directional light and visible landmarks.
light_basis
    The per-pixel light transport as a linear function of the SH light.
differentiable
    The render of the face pixels at fixed ray-cast triangles as a JAX function of
    the geometry (for gradient moves).
jacobian
    Their colours' Jacobian in every continuous scene parameter (forward mode) and the
    reverse-mode gradient of a Gaussian read-out.
pixel_cast
    A private ray cast at other parameters; pixels with fixed triangles.
region
    The interior of a render: away from its silhouette and occlusion contours.

The package imports :mod:`albedo_model` (camera, errors, model, params, pca,
scene_vector) and
:mod:`albedo_model.shading` (effects, image_formation, interpolation); nothing above
``albedo_model``. This file imports :mod:`~albedo_model.render.cache_table`,
:mod:`~albedo_model.render.renderer` and :mod:`~albedo_model.render.state`.
"""

from albedo_model.render.cache_table import STAGE_DEPS
from albedo_model.render.renderer import Renderer, render
from albedo_model.render.state import Rendered, RenderState

__all__ = ["STAGE_DEPS", "Renderer", "Rendered", "RenderState", "render"]
