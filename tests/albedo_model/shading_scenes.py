"""Random scenes, parameters and jaxpr inspection of the shading tests.

Shared by test_image_formation (the full shader) and test_pixel_shading (the
split shader): a random :class:`Scene` of per-vertex data and per-pixel hits,
render parameters, the effect sets every shader is checked with, and helpers
that list a jaxpr's primitives and the inputs it reads.

This module imports only :mod:`albedo_model.params` and
:mod:`albedo_model.shading.image_formation`.
"""

from __future__ import annotations

import jax
import jax.extend
import jax.numpy as jnp
import numpy as np
from scipy.spatial.transform import Rotation

from albedo_model.params import ColorTransform, SHLight, default_square
from albedo_model.shading.image_formation import Effects


N_PIX = 24 * 24


class Scene:
    """Random per-vertex data and per-pixel hits (about a third of the pixels miss)."""

    def __init__(self, seed: int = 0, n: int = 90, m: int = 150, p: int = N_PIX):
        rng = np.random.default_rng(seed)
        normals = rng.normal(size=(n, 3))
        self.normals = (normals / np.linalg.norm(normals, axis=1, keepdims=True)).astype(np.float32)
        self.diffuse = rng.uniform(0.05, 0.9, (n, 3)).astype(np.float32)
        self.specular = rng.uniform(0.0, 0.5, (n, 3)).astype(np.float32)
        self.triangles = rng.integers(0, n, (m, 3)).astype(np.int32)
        self.prim_id = np.where(rng.random(p) < 0.35, -1, rng.integers(0, m, p)).astype(np.int32)
        uv = rng.random((p, 2))
        flip = uv.sum(1) > 1
        uv[flip] = 1 - uv[flip]
        self.bary = uv.astype(np.float32)
        self.ray_dirs = np.column_stack([rng.uniform(-0.3, 0.3, (p, 2)), -np.ones(p)]).astype(
            np.float32)
        self.shadow = rng.uniform(0.0, 1.0, p).astype(np.float32)

    def args(self):
        """Return the shader inputs (triangles ... ray_dirs) as device arrays."""
        return [jnp.asarray(a) for a in (self.triangles, self.normals, self.diffuse, self.specular,
                                         self.prim_id, self.bary, self.ray_dirs)]

    def interp(self, attr: np.ndarray) -> np.ndarray:
        """(P, C) float64 barycentric interpolation at every pixel (misses: triangle 0)."""
        tri = self.triangles[np.maximum(self.prim_id, 0)]
        u, v = self.bary[:, :1].astype(np.float64), self.bary[:, 1:].astype(np.float64)
        a = attr.astype(np.float64)
        return (1 - u - v) * a[tri[:, 0]] + u * a[tri[:, 1]] + v * a[tri[:, 2]]


def rgb_of(shaded) -> np.ndarray:
    """Return the (P, 3) colours of a shader output."""
    return np.stack([np.asarray(c) for c in shaded.rgb], axis=1)


def scene_params(light=None, directional=None, color=None, exponent=20.0, background=(0, 0, 0)):
    """Return default render parameters with the given light, colour transform and exponent."""
    p = default_square()
    p = p._replace(environment_map=light if light is not None else SHLight.frontal(),
                   specular_exponent=exponent)
    if directional is not None:
        p = p._replace(directional_light=directional)
    if color is not None:
        p = p._replace(color_transform=color)
    return p


ROT = Rotation.from_euler("xyz", [0.2, -0.4, 0.1]).as_matrix()


COLOR = ColorTransform(gain=(1.1, 0.9, 1.2), contrast=0.7, offset=(0.01, 0.02, 0.03))


EFFECT_SETS = [
    Effects(),
    Effects(sh_coefficients=4),
    Effects(sh_coefficients=1, clamp=False),
    Effects(specular=True),
    Effects(directional=True),
    Effects(sh_coefficients=0, directional=True, shadows=True, gamma=True),
    Effects(specular=True, color_transform=True),
    Effects(specular=True, directional=True, shadows=True, color_transform=True, gamma=True),
]


def jaxpr_primitives(jaxpr) -> list[str]:
    """List the primitive names of a jaxpr, sub-jaxprs included."""
    names = []
    for eqn in jaxpr.eqns:
        names.append(eqn.primitive.name)
        for sub in jax.extend.core.jaxprs_in_params(eqn.params):
            names += jaxpr_primitives(sub)
    return names


def used_inputs(closed, n_leaves: int) -> set[int]:
    """Return the positions among the first ``n_leaves`` inputs that the jaxpr reads."""
    jaxpr = closed.jaxpr
    used = {id(v) for e in jaxpr.eqns for v in e.invars} | {id(v) for v in jaxpr.outvars}
    return {i for i, v in enumerate(jaxpr.invars[:n_leaves]) if id(v) in used}
