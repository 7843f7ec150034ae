"""Data of the albedo conditional proposal, read from the accepted render state.

:class:`RenderAlbedoData` is the ``data(params)`` callable of
:class:`proposals.albedo_solver.AlbedoConditional`: the render linearised in
the albedo coefficients at the face pixels whose target is not saturated
(:class:`proposals.albedo_solver.AlbedoSystem`). Per pixel, the cached light
transport (:class:`albedo_model.shading.image_formation.PixelLight`: diffuse irradiance,
specular lobe light) multiplies the interpolated diffuse and specular albedo
bases (at most ``n_points`` pixels, a fixed random subset); the colour
transform is returned separately, with the pixel's render
at the model's mean albedo, so that the proposal can drop pixels near the
clamp at 1, also for a scaled light. Pixels
beyond ``n_points`` are dropped in the order of a fixed random permutation
(drawn once from ``seed``). Everything depends on the geometry, pose,
camera, light and colour transform only, never on the albedo coefficients.

This module imports :mod:`albedo_model` and numpy.
"""

from __future__ import annotations

import numpy as np

from albedo_model.errors import InputError
from albedo_model.params import RenderParameter
from albedo_model.render.renderer import Renderer, RenderState
from proposals.albedo_solver import albedo_system

__all__ = ["RenderAlbedoData", "interp"]

_LUMA = np.array([0.3, 0.59, 0.11])
_SATURATED = 0.97
#: The clamp test uses the render at the model's mean albedo plus this many
#: marginal sd (0: the mean; larger values drop more pixels when the light is
#: bright, which made the proposal a poor match in tests).
_HI_SD = 0.0


class RenderAlbedoData:
    """``data(params) -> AlbedoSystem`` (all usable face pixels) or None.

    Parameters
    ----------
    source : object with ``current: RenderState`` (a :class:`~mcmcfit.targets.face.FaceTarget`)
    renderer : Renderer
    target_linear : (H, W, 3) float array
        The linearised target image.
    n_points : int
        Face pixels used (the first in a fixed random order); each stands for
        ``face pixels / n_points`` of them in the proposal's precision.
    seed : int
        Seeds the fixed pixel permutation.
    """

    def __init__(self, source, renderer: Renderer, target_linear: np.ndarray, *,
                 n_points: int = 4000, seed: int = 0):
        self.source, self.renderer = source, renderer
        self._target = np.asarray(target_linear, np.float64).reshape(-1, 3)
        self._ok = np.all(self._target < _SATURATED, axis=1)
        perm = np.random.default_rng(seed).permutation(self._target.shape[0])
        self._rank = np.empty(perm.shape[0], np.int64)  # position of each pixel in perm
        self._rank[perm] = np.arange(perm.shape[0])
        self.n_points = int(n_points)
        model = renderer.model
        n = model.n_vertices
        self._diffuse = (model.diffuse.mean.reshape(n, 3).astype(np.float32),
                         model.diffuse.scaled_basis.reshape(n, 3, -1).astype(np.float32))
        spec = model.specular if (renderer.specular and model.shared_albedo) else None
        self._specular = None if spec is None else (
            spec.mean.reshape(n, 3).astype(np.float32),
            spec.scaled_basis.reshape(n, 3, -1).astype(np.float32))
        # reference albedo per vertex for the clamp test: pixels whose light
        # pushes it past the clamp are left out (a function of the light only)
        hi = model.diffuse.mean.astype(np.float64) + _HI_SD * model.diffuse.marginal_std()
        self._diffuse_hi = hi.reshape(n, 3).astype(np.float32)
        self._specular_hi = None if spec is None else (
            spec.mean.astype(np.float64) + _HI_SD * spec.marginal_std()).reshape(n, 3).astype(
            np.float32)
        self._key: tuple | None = None
        self._value = None
        self._bases_key: tuple | None = None
        self._bases_value = None

    def _state(self, params: RenderParameter) -> RenderState:
        rs = self.source.current
        if rs is None:
            raise InputError("albedo data: the target holds no render state yet")
        p = rs.params
        if p is not params and not (p.pose == params.pose and p.camera == params.camera
                                    and p.color_transform == params.color_transform):
            raise InputError("albedo data requested for a state the renderer does not hold")
        return rs

    def __call__(self, params: RenderParameter):
        rs = self._state(params)
        p = rs.params
        k = len(params.momo.albedo)
        key = (rs.hits, rs.pixel_light, p.color_transform, k)
        if self._key is not None and all(a is b for a, b in zip(self._key[:2], key[:2])) \
                and self._key[2:] == key[2:]:
            return self._value
        self._key, self._value = key, self._compute(rs, p, k)
        return self._value

    @staticmethod
    def _colour(p: RenderParameter, effects) -> tuple[np.ndarray, np.ndarray]:
        """The colour transform as ``c' = M c + off`` (float32; identity when off)."""
        if not effects.color_transform:
            return np.eye(3, dtype=np.float32), np.zeros(3, np.float32)
        ct = p.color_transform
        kappa = float(ct.contrast)
        mat = np.asarray(ct.gain, np.float64)[:, None] * (
            kappa * np.eye(3) + (1.0 - kappa) * np.outer(np.ones(3), _LUMA))
        n_off = 2.0 if effects.specular else 1.0
        return mat.astype(np.float32), (n_off * np.asarray(ct.offset)).astype(np.float32)

    def _bases(self, rs: RenderState, k: int):
        """Face pixels and their interpolated albedo means and bases (cached per ray cast)."""
        hits = rs.hits
        if self._bases_key is not None and self._bases_key[0] is hits and \
                self._bases_key[1] == k:
            return self._bases_value
        face = np.flatnonzero((hits.prim_id >= 0) & self._ok)
        n_face = face.size
        if n_face > self.n_points:  # the first n_points in the fixed random order
            face = face[np.argpartition(self._rank[face], self.n_points)[: self.n_points]]
        tri = self.renderer.model.triangles[hits.prim_id[face]]
        u, v = hits.bary[face, 0].astype(np.float32), hits.bary[face, 1].astype(np.float32)
        w = np.stack([1.0 - u - v, u, v], axis=1)  # (N, 3 corners)
        diffuse = interp(w, tri, *self._diffuse, k)
        specular = None if self._specular is None else interp(w, tri, *self._specular, k)
        ref_d = np.einsum("nk,nkc->nc", w, self._diffuse_hi[tri])
        ref_s = None if self._specular_hi is None else np.einsum("nk,nkc->nc", w,
                                                                  self._specular_hi[tri])
        self._bases_key = (hits, k)
        self._bases_value = (face, diffuse, specular, ref_d, ref_s,
                             n_face / max(face.size, 1))
        return self._bases_value

    def _compute(self, rs: RenderState, p: RenderParameter, k: int):
        hits = rs.hits
        if hits.prim_id.shape[0] != self._target.shape[0]:
            raise InputError("albedo data: render and target image sizes differ")
        if k == 0 or rs.pixel_light.constant is not None:  # a directional Blinn-Phong term
            return None
        face, (md, bd), spec, ref_d, ref_s, weight = self._bases(rs, k)
        if face.size == 0:
            return None
        light = rs.pixel_light
        at = rs.positions(face)  # the light holds the state's pixel set

        def channels(planes):
            return np.stack([np.asarray(c)[at] for c in planes], axis=1).astype(np.float32)

        dl = channels(light.diffuse)
        mean = dl * md
        jac = dl[..., None] * bd
        bright = dl * ref_d
        if spec is not None and light.specular is not None:
            sl = channels(light.specular)
            ms, bs = spec
            mean += sl * ms
            jac += sl[..., None] * bs
            bright += sl * ref_s
        mat, off = self._colour(p, rs.effects)
        if not np.array_equal(mat, np.eye(3, dtype=np.float32)):
            jac = np.einsum("cd,ndj->ncj", mat, jac)
            mean, bright = mean @ mat.T, bright @ mat.T
        return albedo_system(jac, mean, bright, self._target[face].astype(np.float32), off,
                             self._rank[face], face.size, weight)


def interp(w: np.ndarray, tri: np.ndarray, mean: np.ndarray, basis: np.ndarray, k: int):
    """Barycentric interpolation of per-vertex means (n, 3) and bases (n, 3, K) at pixels."""
    m = np.einsum("nk,nkc->nc", w, mean[tri])
    b = np.einsum("nk,nkcj->ncj", w, basis[tri][..., :k] if k < basis.shape[2] else basis[tri])
    return m, b
