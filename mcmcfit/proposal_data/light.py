"""Data of the SH least-squares light proposal, computed from the accepted state it is handed.

:class:`RenderLightData` is the ``solver_data(state) -> (normals, albedo,
target)`` callable of :class:`proposals.light_solver.SHLightSolver`. It takes
up to ``n_points`` face pixels of the accepted render: world-frame normals
(interpolated vertex normals, pose-rotated, renormalised), the diffuse albedo
there (interpolated, linear), and the target colour of the pixel (linearised,
colour transform inverted). The pixels are the first face pixels of a fixed
random permutation of the image (drawn once from ``seed``), so the data are a
deterministic function of the geometry, pose, camera, albedo and colour
transform (``STAGE_DEPS["light_data"]``, on whose version stamps they are
kept), never of the light: the solver's mean is the same for the forward and
the backward move and its transition ratio is exact. Saturated target pixels
are skipped.

This module imports :mod:`albedo_model` (camera, errors, params, render,
shading.effects), :mod:`proposals.base` and :mod:`mcmcfit.proposal_data.face_pixels`.
"""

from __future__ import annotations

import numpy as np

from albedo_model.camera import euler_rotation
from albedo_model.errors import InputError
from albedo_model.params import ColorTransform
from albedo_model.render.cache_table import Kept, stage_key
from albedo_model.render.renderer import Renderer
from albedo_model.shading.effects import offset_count
from mcmcfit.proposal_data.face_pixels import (
    barycentric, corner_weights, render_state_of, unsaturated,
)
from proposals.base import ProposalState

__all__ = ["RenderLightData", "invert_color_transform"]


def invert_color_transform(colours: np.ndarray, ct: ColorTransform, *,
                           n_offsets: float = 1.0) -> np.ndarray:
    """Undo ``c' = gain (kappa c + (1 - kappa) Y(c)) + n_offsets offset``.

    Parameters
    ----------
    colours : (P, 3) float array
    ct : ColorTransform
    n_offsets : float
        2 when the render adds the specular term (AlbedoMM applies the transform
        to diffuse and specular separately, so the offset counts twice:
        :func:`albedo_model.shading.effects.offset_count`).

    Returns
    -------
    (P, 3) float64; NaN when the transform is singular.
    """
    rhs = np.asarray(colours, np.float64) - n_offsets * np.asarray(ct.offset, np.float64)
    try:
        return np.linalg.solve(ct.matrix(), rhs.T).T
    except np.linalg.LinAlgError:
        return np.full_like(rhs, np.nan)


def _vertex_normals(normals, n: int) -> np.ndarray:
    """(n, 3) float64 host copy of a state's vertex normals ((n, 3) or three (n,) arrays)."""
    if isinstance(normals, (tuple, list)):
        return np.stack([np.asarray(c, np.float64) for c in normals], axis=1)
    a = np.asarray(normals, np.float64)
    return a.T if a.shape == (3, n) and n != 3 else a


class RenderLightData:
    """``solver_data(state)`` from the render of the accepted state.

    Parameters
    ----------
    renderer : Renderer
        Renderer of the states (its effects tell whether the offset counts twice).
    target_linear : (H, W, 3) float array
        The linearised target image.
    n_points : int
        Pixels used (about 100-300 are plenty for 27 unknowns).
    seed : int
        Seeds the fixed pixel permutation.
    """

    def __init__(self, renderer: Renderer, target_linear: np.ndarray, *,
                 n_points: int = 200, seed: int = 0):
        self.renderer = renderer
        self._target = np.asarray(target_linear, np.float64).reshape(-1, 3)
        self._ok = unsaturated(self._target)
        self._perm = np.random.default_rng(seed).permutation(self._target.shape[0])
        self.n_points = int(n_points)
        self._kept = Kept()

    def __call__(self, state: ProposalState) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return ``(normals (k, 3) world, albedo (k, 3), target (k, 3))``, k <= n_points."""
        rs = render_state_of(state, "SH light solver data")
        return self._kept.get(stage_key(rs.versions, "light_data"), lambda: self._points(rs))

    def _points(self, rs) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Gather the solver's points of ``rs`` (see the module notes)."""
        p = rs.params
        hits = rs.hits
        if hits.prim_id.shape[0] != self._target.shape[0]:
            raise InputError("light solver data: render and target image sizes differ")
        face = (hits.prim_id[self._perm] >= 0) & self._ok[self._perm]
        pix = self._perm[np.flatnonzero(face)[: self.n_points]]
        tri = self.renderer.model.triangles[hits.prim_id[pix]]
        w = corner_weights(hits, pix, np.float64)
        n = self.renderer.model.n_vertices
        normals_model = barycentric(w, tri, _vertex_normals(rs.normals, n))
        r = euler_rotation(p.pose.roll, p.pose.yaw, p.pose.pitch)
        normals = normals_model @ r.T
        normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
        albedo = barycentric(w, tri, np.asarray(rs.diffuse, np.float64).reshape(-1, 3))
        n_off = offset_count(self.renderer.effects(p))
        target = invert_color_transform(self._target[pix], p.color_transform, n_offsets=n_off)
        return normals, albedo, target
