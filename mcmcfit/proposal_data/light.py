"""Data of the SH least-squares light proposal, read from the accepted render state.

:class:`RenderLightData` is the ``solver_data(params) -> (normals, albedo,
target)`` callable of :class:`proposals.light_solver.SHLightSolver`. It takes
up to ``n_points`` face pixels of the current render: world-frame normals
(interpolated vertex normals, pose-rotated, renormalised), the diffuse albedo
there (interpolated, linear), and the target colour of the pixel (linearised,
colour transform inverted). The pixels are the first face pixels of a fixed
random permutation of the image (drawn once from ``seed``), so the data are a
deterministic function of the geometry, pose, camera, albedo and colour
transform, never of the light: the solver's mean is the same for the forward
and the backward move and its transition ratio is exact. Saturated target
pixels (a linear channel >= 0.97) are skipped.

This module imports :mod:`albedo_model` and numpy.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from albedo_model.camera import euler_rotation
from albedo_model.errors import InputError
from albedo_model.params import ColorTransform, RenderParameter
from albedo_model.render.renderer import Renderer, RenderState

__all__ = ["RenderLightData", "invert_color_transform"]

_LUMA = np.array([0.3, 0.59, 0.11])
_SATURATED = 0.97


def invert_color_transform(colours: np.ndarray, ct: ColorTransform, *,
                           n_offsets: float = 1.0) -> np.ndarray:
    """Undo ``c' = gain (kappa c + (1 - kappa) Y(c)) + n_offsets offset``.

    Parameters
    ----------
    colours : (P, 3) float array
    ct : ColorTransform
    n_offsets : float
        2 when the render adds the specular term (AlbedoMM applies the transform
        to diffuse and specular separately, so the offset counts twice).

    Returns
    -------
    (P, 3) float64; NaN when the transform is singular.
    """
    gain = np.asarray(ct.gain, np.float64)
    k = float(ct.contrast)
    m = gain[:, None] * (k * np.eye(3) + (1.0 - k) * np.outer(np.ones(3), _LUMA))
    rhs = np.asarray(colours, np.float64) - n_offsets * np.asarray(ct.offset, np.float64)
    try:
        return np.linalg.solve(m, rhs.T).T
    except np.linalg.LinAlgError:
        return np.full_like(rhs, np.nan)


def _vertex_normals(normals, n: int) -> np.ndarray:
    """(n, 3) float64 host copy of a state's vertex normals ((n, 3) or three (n,) arrays)."""
    if isinstance(normals, (tuple, list)):
        return np.stack([np.asarray(c, np.float64) for c in normals], axis=1)
    a = np.asarray(normals, np.float64)
    return a.T if a.shape == (3, n) and n != 3 else a


class _Current(Protocol):
    current: RenderState | None


class RenderLightData:
    """``solver_data(params)`` from the accepted render state of a target.

    Parameters
    ----------
    source : object with ``current: RenderState`` (e.g. :class:`~mcmcfit.targets.face.FaceTarget`)
    renderer : Renderer
        Renderer of that state (its effects tell whether the offset counts twice).
    target_linear : (H, W, 3) float array
        The linearised target image.
    n_points : int
        Pixels used (about 100-300 are plenty for 27 unknowns).
    seed : int
        Seeds the fixed pixel permutation.
    """

    def __init__(self, source: _Current, renderer: Renderer, target_linear: np.ndarray, *,
                 n_points: int = 200, seed: int = 0):
        self.source, self.renderer = source, renderer
        lin = np.asarray(target_linear, np.float64)
        self._target = lin.reshape(-1, 3)
        self._ok = np.all(self._target < _SATURATED, axis=1)
        self._perm = np.random.default_rng(seed).permutation(self._target.shape[0])
        self.n_points = int(n_points)
        self._key: tuple | None = None
        self._value: tuple | None = None

    def _state(self, params: RenderParameter) -> RenderState:
        rs = self.source.current
        if rs is None:
            raise InputError("light solver data: the target holds no render state yet")
        p = rs.params
        if p is params:
            return rs
        same = (p.pose == params.pose and p.camera == params.camera
                and p.color_transform == params.color_transform
                and all(np.array_equal(a, b) for a, b in zip(p.momo[:3], params.momo[:3])))
        if not same:
            raise InputError("light solver data requested for a state the renderer does not hold")
        return rs

    def __call__(self, params: RenderParameter) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(normals (k, 3) world, albedo (k, 3), target (k, 3))`` with k <= n_points."""
        rs = self._state(params)
        p = rs.params
        key = (rs.hits, rs.normals, rs.diffuse, p.pose, p.color_transform)
        if self._key is not None and all(a is b for a, b in zip(self._key[:3], key[:3])) \
                and self._key[3:] == key[3:]:
            return self._value
        hits = rs.hits
        if hits.prim_id.shape[0] != self._target.shape[0]:
            raise InputError("light solver data: render and target image sizes differ")
        face = (hits.prim_id[self._perm] >= 0) & self._ok[self._perm]
        pix = self._perm[np.flatnonzero(face)[: self.n_points]]
        tri = self.renderer.model.triangles[hits.prim_id[pix]]
        u, v = hits.bary[pix, 0:1].astype(np.float64), hits.bary[pix, 1:2].astype(np.float64)
        w = 1.0 - u - v

        def interp(attr: np.ndarray) -> np.ndarray:
            return w * attr[tri[:, 0]] + u * attr[tri[:, 1]] + v * attr[tri[:, 2]]

        normals_model = interp(_vertex_normals(rs.normals, self.renderer.model.n_vertices))
        r = euler_rotation(p.pose.roll, p.pose.yaw, p.pose.pitch)
        normals = normals_model @ r.T
        normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
        albedo = interp(np.asarray(rs.diffuse, np.float64).reshape(-1, 3))
        n_off = 2.0 if self.renderer.effects(p).specular else 1.0
        target = invert_color_transform(self._target[pix], p.color_transform, n_offsets=n_off)
        self._key, self._value = key, (normals, albedo, target)
        return self._value
