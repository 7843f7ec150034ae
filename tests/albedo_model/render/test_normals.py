"""Vertex normals on the device and their tangents against independent references."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import trimesh

from albedo_model.model import vertex_normals
from albedo_model.render.normals import (
    vertex_normal_columns, vertex_normal_tangents, vertex_normals_jax,
)


def _mesh():
    """A bumpy icosphere (non-uniform triangles) plus one degenerate and one unused vertex."""
    sphere = trimesh.creation.icosphere(subdivisions=2)
    rng = np.random.default_rng(0)
    v = sphere.vertices * (1.0 + 0.1 * rng.normal(size=(len(sphere.vertices), 1)))
    f = sphere.faces
    n = len(v)
    v = np.vstack([v, [[3.0, 0.0, 0.0], [3.0, 0.0, 0.0], [3.0, 1.0, 0.0], [9.0, 9.0, 9.0]]])
    f = np.vstack([f, [[n, n + 1, n + 2]]])  # zero area: its vertices keep the fallback normal
    return v.astype(np.float32), f.astype(np.int32)


def test_device_normals_are_the_models():
    v, f = _mesh()
    ours = np.asarray(vertex_normals_jax(jnp.asarray(v), jnp.asarray(f)))
    np.testing.assert_allclose(ours[:-4], vertex_normals(v, f)[:-4], atol=2e-6)
    np.testing.assert_array_equal(ours[-1], [0.0, 0.0, 1.0])  # no triangle at all


def test_tangents_are_the_jvp_along_every_direction():
    v, f = _mesh()
    rng = np.random.default_rng(1)
    k = 7
    dv = rng.normal(size=(len(v), 3, k)).astype(np.float32)
    ours = vertex_normal_tangents(jnp.asarray(v), jnp.asarray(f), jnp.asarray(dv))
    for j in range(k):
        _, ref = jax.jvp(lambda x: vertex_normal_columns(x, jnp.asarray(f)),
                         (jnp.asarray(v),), (jnp.asarray(dv[..., j]),))
        for c in range(3):
            np.testing.assert_allclose(np.asarray(ours[c])[:, j], np.asarray(ref[c]),
                                       rtol=1e-4, atol=1e-5)


def test_tangents_match_central_differences():
    """Independent of JAX's derivative rules: (n(v + h d) - n(v - h d)) / 2h in float64."""
    v, f = _mesh()
    v, f = v[:-4], f[:-1]  # the smooth part
    d = np.random.default_rng(2).normal(size=v.shape)
    ours = vertex_normal_tangents(jnp.asarray(v), jnp.asarray(f), jnp.asarray(d[..., None],
                                                                           jnp.float32))
    h = 1e-5
    v64 = v.astype(np.float64)
    ref = (vertex_normals(v64 + h * d, f) - vertex_normals(v64 - h * d, f)) / (2 * h)
    got = np.stack([np.asarray(c)[:, 0] for c in ours], axis=1)
    np.testing.assert_allclose(got, ref, atol=2e-3 * np.abs(ref).max())
