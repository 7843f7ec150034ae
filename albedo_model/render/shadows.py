"""Cast shadows of a render state's directional light, cast once per geometry, camera and light direction.

A state's shadow is the visibility of the directional light at its pixel set
(:func:`~albedo_model.render.visibility.directional_visibility`: one occlusion
ray per face pixel, a few for a soft edge, against the scene the state's
geometry lives in). It is keyed on the ``shadow`` row of :data:`~albedo_model.render.cache_table.STAGE_DEPS`
(geometry, pose, camera, the directional light's direction): an SH light,
albedo, colour or directional-strength move reuses the shadow of the state it
starts from, a light-direction move re-casts
only the shadow rays (no primary ray, no BVH work), and an effect set without
shadows casts none.

This module imports :mod:`albedo_model.render` (cache_table, raycast, state,
visibility) and :mod:`albedo_model.shading.effects`.
"""

from __future__ import annotations

import numpy as np

from albedo_model.render.cache_table import stage_key
from albedo_model.render.raycast import RayCaster
from albedo_model.render.state import RenderState
from albedo_model.render.visibility import directional_visibility
from albedo_model.shading.effects import Effects

__all__ = ["state_shadow"]


def state_shadow(state: RenderState, effects: Effects, caster: RayCaster,
                 triangles: np.ndarray, counts: dict | None = None, *, rays: int = 1,
                 spread_deg: float = 0.0) -> tuple | None:
    """Return ``(key, (C,) float32 visibility at the state's pixel set)``, or None without shadows.

    Parameters
    ----------
    state : RenderState
        Its ``shadow`` is returned as is when its key is the state's.
    effects : Effects
        No shadow is cast unless ``effects.shadows``.
    caster : RayCaster
        The scene holding the state's geometry.
    triangles : (m, 3) int array
    counts : dict, optional
        ``counts["shadow"]`` is incremented by the number of rays cast.
    rays, spread_deg : int, float
        Shadow rays per face pixel over a light of this angular radius (a soft
        edge; :func:`~albedo_model.render.visibility.shadow_directions`).
    """
    if not effects.shadows:
        return None
    key = stage_key(state.versions, "shadow")
    if state.shadow is not None and state.shadow[0] == key:
        return state.shadow
    p = state.params
    if counts is not None:
        counts["shadow"] = counts.get("shadow", 0) + rays * int(
            np.count_nonzero(state.hits.prim_id >= 0))
    shadow = directional_visibility(state.hits, state.shape.reshape(-1, 3), triangles, p.pose,
                                    p.directional_light.direction, caster, rays=rays,
                                    spread_deg=spread_deg)
    if state.pixels is not None:
        shadow = shadow[state.pixels]
    return key, shadow
