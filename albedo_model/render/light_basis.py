"""The per-pixel light transport of a render state as a linear function of the SH light.

The SH part of the light transport (:func:`albedo_model.shading.image_formation.pixel_light`)
is linear in the environment map ``L`` (K, 3), the same per channel:
``diffuse_c(p) = sum_i B_i(p) L_ic`` and ``specular_c(p) = sum_i S_i(p) L_ic``
(Lambert-convolved SH at the normal, and the lobe times SH at AlbedoMM's
reflection direction). :func:`light_basis` evaluates ``B`` and ``S`` at the
state's pixel set with the state's own compiled light stage, three basis
functions per call (one per colour channel), so that they agree with the
renderer to float32 rounding. A directional light is not linear in ``L``: the
basis is that of the SH light alone (the directional term is an offset that
the caller reads off the state's light transport).

This module imports :mod:`albedo_model` (camera, params, shading.scalars) and
:mod:`albedo_model.render` (stages, state).
"""

from __future__ import annotations

import numpy as np

from albedo_model.camera import euler_rotation
from albedo_model.params import DirectionalLight, SHLight
from albedo_model.render.stages import light_effects, light_stage
from albedo_model.render.state import RenderState
from albedo_model.shading.scalars import pack_shading_params

__all__ = ["light_basis"]


def light_basis(state: RenderState) -> tuple[np.ndarray, np.ndarray | None] | None:
    """Return ``(B (C, K), S (C, K) or None)`` of the state's pixel set, or None.

    Parameters
    ----------
    state : RenderState
        A render state (its per-pixel geometry is read).

    Returns
    -------
    B : (C, K) float32
        Diffuse transport of each SH coefficient at the C pixels of the set.
    S : (C, K) float32 or None
        Specular transport (None when the specular term is off).
    None
        When the scene has no SH light.
    """
    effects = light_effects(state.effects)._replace(directional=False, shadows=False,
                                                    directional_specular_map=False)
    k = effects.sh_coefficients
    if k == 0:
        return None
    p = state.params._replace(directional_light=DirectionalLight())
    rotation = euler_rotation(p.pose.roll, p.pose.yaw, p.pose.pitch)
    stage = light_stage(effects)
    geometry = state.pixel_geometry.value
    n_calls = -(-k // 3)
    diffuse, specular = [], []
    for j in range(n_calls):
        unit = np.zeros((k, 3))
        for c in range(3):
            if 3 * j + c < k:
                unit[3 * j + c, c] = 1.0
        packed = pack_shading_params(p._replace(environment_map=SHLight(unit)), rotation)
        out = stage(geometry, packed, None)
        for c in range(3):
            if 3 * j + c < k:
                diffuse.append(np.asarray(out.diffuse[c]))
                if out.specular is not None:
                    specular.append(np.asarray(out.specular[c]))
    b = np.stack(diffuse, axis=1).astype(np.float32)
    s = np.stack(specular, axis=1).astype(np.float32) if specular else None
    return b, s
