"""Vertex normals on the device (JAX), for the shape/expression hot path.

Same convention as :func:`albedo_model.model.vertex_normals` (renormalised mean
of adjacent unit face normals, scalismo's rule). This module imports nothing
from the project.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

__all__ = ["vertex_normals_jax"]


@jax.jit
def vertex_normals_jax(vertices: jax.Array, triangles: jax.Array) -> jax.Array:
    """Unit vertex normals.

    Parameters
    ----------
    vertices : (n, 3) float32, any frame
    triangles : (m, 3) int32, counter-clockwise seen from outside

    Returns
    -------
    (n, 3) float32
        (0, 0, 1) for vertices without a non-degenerate adjacent triangle.
    """
    n = vertices.shape[0]
    a = vertices[triangles[:, 0]]
    e1 = vertices[triangles[:, 1]] - a
    e2 = vertices[triangles[:, 2]] - a
    fn = jnp.cross(e1, e2)
    norm = jnp.sqrt(jnp.sum(fn * fn, axis=1, keepdims=True))
    fn = jnp.where(norm > 0, fn / jnp.maximum(norm, 1e-30), 0.0)
    acc = jnp.zeros((n, 3), vertices.dtype)
    for j in range(3):
        acc = acc.at[triangles[:, j]].add(fn)
    length = jnp.sqrt(jnp.sum(acc * acc, axis=1, keepdims=True))
    fallback = jnp.array([0.0, 0.0, 1.0], vertices.dtype)
    return jnp.where(length > 1e-12, acc / jnp.maximum(length, 1e-30), fallback)
