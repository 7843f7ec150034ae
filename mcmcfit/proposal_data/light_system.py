"""Data of the SH light's exact conditional, computed from the accepted state it is handed.

:class:`RenderLightSystem` is the ``data(state)`` callable of
:class:`proposals.light_conditional.LightConditional`: at every face pixel of
the accepted render whose target is not saturated, the transport of each SH
coefficient (:func:`albedo_model.render.light_basis.light_basis`) times the
pixel's diffuse and specular albedo, reduced to the normal equations with the
colour transform (:func:`proposals.light_conditional.light_system`). It
depends on the blocks of ``STAGE_DEPS["light_system"]`` only (never on the
light; a directional light enters as an offset, or with ``directional`` as the
(K+1)-th row of the transport, its strength drawn with the SH light), on whose
version stamps it is kept.

This module imports :mod:`albedo_model` (errors, render, shading.effects),
:mod:`proposals` (light_conditional, base) and :mod:`mcmcfit.proposal_data.face_pixels`.
"""

from __future__ import annotations

import numpy as np

from albedo_model.errors import InputError
from albedo_model.render.cache_table import Kept, stage_key
from albedo_model.render.light_basis import light_basis
from albedo_model.render.state import RenderState
from albedo_model.shading.effects import offset_count
from mcmcfit.proposal_data.face_pixels import render_state_of, unsaturated
from proposals.base import ProposalState
from proposals.light_conditional import LightSystem, light_system

__all__ = ["RenderLightSystem"]


class RenderLightSystem:
    """``data(state) -> LightSystem`` over all usable face pixels of the accepted render, or None.

    Parameters
    ----------
    target_linear : (H, W, 3) float array
        The linearised target image.
    region : (H W,) bool array, optional
        Use only these pixels (a region likelihood's); default: every face pixel.
    weights : (H W,) float array, optional
        Fixed per-pixel weights (a robust foreground's face probabilities at
        the mode): each pixel's rows scaled by their square root.
    directional : bool
        Put a directional light's strength into the system (when its highlight
        has its diffuse colour and every channel is positive); else it is an offset.
    """

    def __init__(self, target_linear: np.ndarray, *, region: np.ndarray | None = None,
                 weights: np.ndarray | None = None, directional: bool = False):
        self._directional = bool(directional)
        self._root_weights = None if weights is None else np.sqrt(
            np.asarray(weights, np.float64).reshape(-1))
        self._target = np.asarray(target_linear, np.float64).reshape(-1, 3)
        self._ok = unsaturated(self._target)
        if region is not None:
            self._ok &= np.asarray(region, bool).reshape(-1)
        self._system = Kept()

    def __call__(self, state: ProposalState) -> LightSystem | None:
        """Return the light system of the accepted ``state``'s render (None: nothing to draw)."""
        rs = render_state_of(state, "light conditional data")
        key = stage_key(rs.versions, "light_system")
        return self._system.get(key, lambda: self._compute(rs, key))

    def _compute(self, rs: RenderState, key: tuple) -> LightSystem | None:
        hits = rs.hits
        if hits.prim_id.shape[0] != self._target.shape[0]:
            raise InputError("light conditional data: render and target image sizes differ")
        basis = light_basis(rs)
        if basis is None:
            return None
        face = np.flatnonzero((hits.prim_id >= 0) & self._ok)
        if face.size == 0:
            return None
        at = rs.positions(face)
        b, s = basis
        albedo = rs.pixel_albedo.value
        rho = np.stack([np.asarray(c)[at] for c in albedo.diffuse], axis=1)  # (N, 3)
        g = rho[:, :, None] * b[at][:, None, :]
        if s is not None and albedo.specular is not None:
            spec = np.stack([np.asarray(c)[at] for c in albedo.specular], axis=1)
            g = g + spec[:, :, None] * s[at][:, None, :]
        p = rs.params
        if rs.effects.color_transform:
            mat = p.color_transform.matrix()
            off = offset_count(rs.effects) * np.asarray(p.color_transform.offset, np.float64)
        else:
            mat, off = np.eye(3), np.zeros(3)
        target = self._target[face] - off
        drawn, held = False, not rs.effects.color_transform
        if rs.effects.directional:  # the state's transport minus the SH part
            part = _directional_part(rs, at, rho, albedo, b, s)
            strength = np.asarray(p.directional_light.diffuse, np.float64)
            drawn = (self._directional and bool(np.all(strength > 0.0))
                     and np.array_equal(strength, np.asarray(p.directional_light.specular)))
            if drawn:  # linear in the strength: its unit transport is one more row of L
                g = np.concatenate([g, (part / strength)[:, :, None]], axis=2)
            else:  # an offset (one that depends on the colour matrix)
                target, held = target - part @ mat.T, True
        if self._root_weights is not None:
            sw = self._root_weights[face]
            g, target = g * sw[:, None, None], target * sw[:, None]
        return light_system(g, mat, target, key, directional=drawn, matrix_free_target=not held)


def _directional_part(rs: RenderState, at, rho, albedo, b, s) -> np.ndarray:
    """(N, 3) the directional light's share of the render (before the colour transform)."""
    light = rs.pixel_light.value
    L = np.asarray(rs.params.environment_map.coefficients, np.float64)
    out = np.empty(rho.shape)
    for c in range(3):
        d = np.asarray(light.diffuse[c], np.float64)[at] - b[at] @ L[:, c]
        out[:, c] = rho[:, c] * d
        spec_light = light.specular
        if spec_light is not None and albedo.specular is not None:
            sh = s[at] @ L[:, c] if s is not None else 0.0
            out[:, c] += (np.asarray(albedo.specular[c], np.float64)[at]
                          * (np.asarray(spec_light[c], np.float64)[at] - sh))
    return out
