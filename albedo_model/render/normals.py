"""Vertex normals on the device (JAX), for the shape/expression hot path.

Same convention as :func:`albedo_model.model.vertex_normals` (renormalised sum
of adjacent unit face normals, scalismo's rule). The code works per component
on (m,) and (n,) arrays and accumulates with nine scalar scatter-adds: XLA-CPU
runs that about 2.5x faster than one scatter of (m, 3) rows (measured on a
53k-vertex mesh: 2.2 ms vs 5.8 ms).

This module imports nothing from the project.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

__all__ = ["vertex_normal_columns", "vertex_normal_tangents", "vertex_normals_jax"]

_EPS = 1e-30


def vertex_normal_columns(vertices: jax.Array, triangles: jax.Array) -> tuple:
    """Compute unit vertex normals as three (n,) arrays (pure; compose it inside a ``jit``).

    Parameters
    ----------
    vertices : (n, 3) float32, any frame
    triangles : (m, 3) int32, counter-clockwise seen from outside

    Returns
    -------
    (nx, ny, nz) : three (n,) arrays, dtype of ``vertices``
        (0, 0, 1) for vertices without a non-degenerate adjacent triangle.
    """
    v = [vertices[:, c] for c in range(3)]
    t = [triangles[:, j] for j in range(3)]
    a = [vc[t[0]] for vc in v]
    e1 = [vc[t[1]] - ac for vc, ac in zip(v, a)]
    e2 = [vc[t[2]] - ac for vc, ac in zip(v, a)]
    face = (e1[1] * e2[2] - e1[2] * e2[1],
            e1[2] * e2[0] - e1[0] * e2[2],
            e1[0] * e2[1] - e1[1] * e2[0])
    sq = face[0] * face[0] + face[1] * face[1] + face[2] * face[2]
    inv = jnp.where(sq > 0, jax.lax.rsqrt(jnp.maximum(sq, _EPS)), 0.0)
    n = vertices.shape[0]
    acc = []
    for fc in face:
        unit = fc * inv
        total = jnp.zeros(n, vertices.dtype)
        for tj in t:
            total = total.at[tj].add(unit)
        acc.append(total)
    sq = acc[0] * acc[0] + acc[1] * acc[1] + acc[2] * acc[2]
    ok = sq > 1e-24
    inv = jax.lax.rsqrt(jnp.maximum(sq, _EPS))
    return (jnp.where(ok, acc[0] * inv, 0.0), jnp.where(ok, acc[1] * inv, 0.0),
            jnp.where(ok, acc[2] * inv, 1.0))


def vertex_normal_tangents(vertices: jax.Array, triangles: jax.Array,
                           tangents: jax.Array) -> tuple:
    """Differentiate :func:`vertex_normal_columns` along K vertex directions at once (pure).

    The same maths as ``jax.jvp`` of :func:`vertex_normal_columns` under
    ``vmap``, written with the directions as the trailing, contiguous axis:
    XLA-CPU scatters (m, K) rows far faster than K batched scalar scatters
    (about 25 % less time for K = 43 on the 19k-vertex default model).

    Parameters
    ----------
    vertices : (n, 3) float32
    triangles : (m, 3) int32
    tangents : (n, 3, K) float32
        Each direction's vertex displacements.

    Returns
    -------
    (dnx, dny, dnz) : three (n, K) arrays
        Zero where :func:`vertex_normal_columns` falls back to (0, 0, 1).
    """
    t0, t1, t2 = (triangles[:, j] for j in range(3))
    a = vertices[t0]
    e1, e2 = vertices[t1] - a, vertices[t2] - a
    da = tangents[t0]
    d1, d2 = tangents[t1] - da, tangents[t2] - da
    face = jnp.cross(e1, e2)
    dface = (jnp.cross(d1, e2[:, :, None], axisa=1, axisb=1, axisc=1)
             + jnp.cross(e1[:, :, None], d2, axisa=1, axisb=1, axisc=1))
    sq = jnp.sum(face * face, axis=1)
    inv = jnp.where(sq > 0, jax.lax.rsqrt(jnp.maximum(sq, _EPS)), 0.0)
    unit = face * inv[:, None]
    dunit = _unit_tangent(unit, dface, inv)
    n = vertices.shape[0]
    acc = jnp.zeros((n, 3), vertices.dtype)
    dacc = jnp.zeros((n, 3, tangents.shape[-1]), vertices.dtype)
    for tj in (t0, t1, t2):
        acc = acc.at[tj].add(unit)
        dacc = dacc.at[tj].add(dunit)
    sq = jnp.sum(acc * acc, axis=1)
    inv = jax.lax.rsqrt(jnp.maximum(sq, _EPS))
    dnormal = jnp.where((sq > 1e-24)[:, None, None], _unit_tangent(acc * inv[:, None], dacc, inv),
                        0.0)
    return dnormal[:, 0], dnormal[:, 1], dnormal[:, 2]


def _unit_tangent(unit: jax.Array, d: jax.Array, inv_norm: jax.Array) -> jax.Array:
    """Return the derivative of ``w / |w|`` along ``d`` (rows, K directions).

    ``unit`` is ``w / |w|`` and ``inv_norm`` is ``1 / |w|``.
    """
    along = jnp.einsum("rc,rck->rk", unit, d)
    return (d - unit[:, :, None] * along[:, None, :]) * inv_norm[:, None, None]


@jax.jit
def vertex_normals_jax(vertices: jax.Array, triangles: jax.Array) -> jax.Array:
    """Compute unit vertex normals.

    Parameters
    ----------
    vertices : (n, 3) float32, any frame
    triangles : (m, 3) int32, counter-clockwise seen from outside

    Returns
    -------
    (n, 3) float32
        (0, 0, 1) for vertices without a non-degenerate adjacent triangle.
    """
    return jnp.stack(vertex_normal_columns(vertices, triangles), axis=1)
