"""Textures: per-vertex values baked into images through a model's UV atlas, and sampled back.

Modules
-------
bake
    Baking per-vertex values into a square texture (Embree looks up each texel's
    triangle), and bilinear sampling of a texture at UV points.

This package imports :mod:`albedo_model` (``errors``, ``uv_atlas``) and
:mod:`albedo_model.render.raycast`.
"""
