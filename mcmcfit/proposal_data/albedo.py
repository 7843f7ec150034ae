"""Data of the albedo conditional proposal, computed from the accepted state it is handed.

:class:`RenderAlbedoData` is the ``data(state)`` callable of
:class:`proposals.albedo_solver.AlbedoConditional`: the render linearised in
the albedo coefficients at the face pixels whose target is not saturated
(:class:`proposals.albedo_solver.AlbedoSystem`). Per pixel, the cached light
transport (:class:`albedo_model.shading.image_formation.PixelLight`: diffuse
irradiance, specular lobe light) multiplies the interpolated diffuse and
specular albedo bases (at most ``n_points`` pixels, a fixed random subset); the
colour transform is returned separately, with the pixel's render at the
model's mean albedo, so that the proposal can drop pixels near the clamp at 1,
also for a scaled light. Pixels beyond ``n_points`` are dropped in the order of
a fixed random permutation (drawn once from ``seed``). Everything depends on
the geometry, pose, camera, light and colour transform only, never on the
albedo coefficients: the system is kept while the version stamps of the
blocks of ``STAGE_DEPS["albedo_system"]`` are (the face pixels' bases while
those of ``"albedo_bases"`` are; :mod:`albedo_model.render.cache_table`).

This module imports :mod:`albedo_model` (errors, params, render, shading.effects),
:mod:`proposals` (albedo_solver, base) and :mod:`mcmcfit.proposal_data.face_pixels`.
"""

from __future__ import annotations

import numpy as np

from albedo_model.errors import InputError
from albedo_model.params import RenderParameter
from albedo_model.render.cache_table import Kept, stage_key
from albedo_model.render.renderer import Renderer
from albedo_model.render.state import RenderState
from albedo_model.shading.effects import Effects, offset_count
from mcmcfit.proposal_data.face_pixels import (
    barycentric, corner_weights, render_state_of, unsaturated,
)
from proposals.albedo_solver import AlbedoSystem, albedo_system
from proposals.base import ProposalState

__all__ = ["RenderAlbedoData"]

#: The clamp test uses the render at the model's mean albedo plus this many
#: marginal sd (0: the mean; larger values drop more pixels when the light is
#: bright, which made the proposal a poor match in tests).
_HI_SD = 0.0


class RenderAlbedoData:
    """``data(state) -> AlbedoSystem`` (all usable face pixels of the accepted render) or None.

    Parameters
    ----------
    renderer : Renderer
        The renderer of the states it is handed (its model and effects).
    target_linear : (H, W, 3) float array
        The linearised target image.
    n_points : int
        Face pixels used (the first in a fixed random order); each stands for
        ``face pixels / n_points`` of them in the proposal's precision.
    seed : int
        Seeds the fixed pixel permutation.
    region : (H W,) bool array, optional
        Use only these pixels (the fixed region of a region likelihood,
        :class:`mcmcfit.targets.image.ImageLikelihood`); default: every face pixel.
    weights : (H W,) float array, optional
        Fixed per-pixel weights of the Gaussian system (a robust foreground's
        face probabilities at the mode): each pixel's rows scaled by their
        square root. Fixed, so the draw stays an exact MH proposal.
    """

    def __init__(self, renderer: Renderer, target_linear: np.ndarray, *,
                 n_points: int = 4000, seed: int = 0, region: np.ndarray | None = None,
                 weights: np.ndarray | None = None):
        self.renderer = renderer
        self._root_weights = None if weights is None else np.sqrt(
            np.asarray(weights, np.float64).reshape(-1)).astype(np.float32)
        self._target = np.asarray(target_linear, np.float64).reshape(-1, 3)
        self._ok = unsaturated(self._target)
        if region is not None:
            self._ok &= np.asarray(region, bool).reshape(-1)
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
        self._system = Kept()  # the AlbedoSystem (or None)
        self._bases = Kept()  # face pixels and their bases

    def __call__(self, state: ProposalState) -> AlbedoSystem | None:
        """Return the albedo system of the accepted ``state``'s render (None: nothing to draw)."""
        rs = render_state_of(state, "albedo conditional data")
        k = len(state.params.momo.albedo)
        key = (stage_key(rs.versions, "albedo_system"), k)
        return self._system.get(key, lambda: self._compute(rs, state.params, k, key))

    @staticmethod
    def _colour(p: RenderParameter, effects: Effects) -> tuple[np.ndarray, np.ndarray]:
        """Return the colour transform as ``c' = M c + off`` (float32; identity when off)."""
        if not effects.color_transform:
            return np.eye(3, dtype=np.float32), np.zeros(3, np.float32)
        ct = p.color_transform
        return (ct.matrix().astype(np.float32),
                (offset_count(effects) * np.asarray(ct.offset)).astype(np.float32))

    def _face_bases(self, rs: RenderState, k: int):
        """Face pixels and their interpolated albedo means and bases (kept per ray cast)."""
        return self._bases.get((stage_key(rs.versions, "albedo_bases"), k),
                               lambda: self._interpolate_bases(rs, k))

    def _interpolate_bases(self, rs: RenderState, k: int):
        hits = rs.hits
        face = np.flatnonzero((hits.prim_id >= 0) & self._ok)
        n_face = face.size
        if n_face > self.n_points:  # the first n_points in the fixed random order
            face = face[np.argpartition(self._rank[face], self.n_points)[: self.n_points]]
        tri = self.renderer.model.triangles[hits.prim_id[face]]
        w = corner_weights(hits, face)

        def at_pixels(mean_basis):
            mean, basis = mean_basis
            return barycentric(w, tri, mean), barycentric(w, tri, basis[..., :k])

        diffuse = at_pixels(self._diffuse)
        specular = None if self._specular is None else at_pixels(self._specular)
        ref_d = barycentric(w, tri, self._diffuse_hi)
        ref_s = None if self._specular_hi is None else barycentric(w, tri, self._specular_hi)
        return face, diffuse, specular, ref_d, ref_s, n_face / max(face.size, 1)

    def _compute(self, rs: RenderState, p: RenderParameter, k: int, key: tuple):
        hits = rs.hits
        if hits.prim_id.shape[0] != self._target.shape[0]:
            raise InputError("albedo data: render and target image sizes differ")
        if k == 0 or rs.pixel_light.constant is not None:  # a directional Blinn-Phong term
            return None
        face, (md, bd), spec, ref_d, ref_s, weight = self._face_bases(rs, k)
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
        target = self._target[face].astype(np.float32)
        row_weights = None
        if self._root_weights is not None:  # rows scaled: the residual t - s r0 - o becomes
            sw = self._root_weights[face][:, None]  # sw (t - s r0 - o), the clamp test kept
            jac, mean = jac * sw[..., None], mean * sw
            target = (target - off) * sw + off
            row_weights = sw[:, 0]
        count = offset_count(rs.effects) if rs.effects.color_transform else 0.0
        return albedo_system(jac, mean, bright, target, off, self._rank[face], face.size, weight,
                             key, offset_count=count, row_weights=row_weights)
