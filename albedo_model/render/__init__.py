"""Forming an image of a model instance by ray casting, with caches driven by parameter blocks.

Modules
-------
cache_table
    The one stage -> blocks table: which parameter blocks each cached product reads.
renderer
    :class:`Renderer`: the stages of a render, recomputed only where a move's
    blocks make them stale; :func:`render`, one uncached image.
state
    :class:`RenderState`, what a renderer caches per scene, and the per-pixel
    :class:`Deferred` caches.
stages
    The jitted stages (normals, pixel hits, geometry, albedo, light, image).
instances
    Shape and albedo instances, updated by coefficient-block deltas.
raycast, embree_refit, scene_slots
    Embree ray casting (the only ``embreex`` importer), in-place BVH refit, and
    the double-buffered scenes that make a rejected geometry move free.
normals
    Vertex normals on the device.
visibility
    Cast shadows of a directional light and visible landmarks.

Imports :mod:`albedo_model` (model, params, camera, errors) and
:mod:`albedo_model.shading`; nothing above ``albedo_model``.
"""

from albedo_model.render.cache_table import STAGE_DEPS
from albedo_model.render.renderer import Renderer, render
from albedo_model.render.state import Rendered, RenderState

__all__ = ["STAGE_DEPS", "Renderer", "Rendered", "RenderState", "render"]
