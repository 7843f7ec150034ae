"""Which effects a scene's image formation computes (:class:`Effects`), and for which scene.

An :class:`Effects` value is hashable and static under ``jit``: the shading
code is traced once per value, and a switched-off effect is not traced at all.

This module imports only :mod:`albedo_model.params` and :mod:`albedo_model.sh`.
"""

from __future__ import annotations

from typing import NamedTuple

from albedo_model.params import RenderParameter
from albedo_model.sh import MAX_SH_COEFFICIENTS

__all__ = ["Effects", "effects_for", "offset_count"]


class Effects(NamedTuple):
    """Which effects a scene's image formation computes (hashable; one compiled shader each).

    Attributes
    ----------
    sh_coefficients : int
        Number of SH coefficients used, 0..9 (``min(K, 9)``); 0 turns SH light off.
    specular : bool
        AlbedoMM specular term (needs per-vertex specular albedo).
    directional : bool
        scalismo's directional light (Lambert + Blinn-Phong), added to the SH light.
    shadows : bool
        Multiply the directional diffuse and specular terms by a per-pixel
        visibility (needs ``directional``).
    color_transform : bool
        Apply gain / contrast / offset (off = identity).
    gamma : bool
        Encode the clamped image with ``x^(1/2.2)`` (off = linear output, as fitted).
    clamp : bool
        Clamp ``D + S`` to [0, 1] (AlbedoMM does; the plain scalismo renderer does not).
    directional_specular_map : bool
        Scale the directional light's Blinn-Phong term by the per-vertex specular
        albedo (the paper's appendix renders; needs ``directional``).
    """

    sh_coefficients: int = 9
    specular: bool = False
    directional: bool = False
    shadows: bool = False
    color_transform: bool = False
    gamma: bool = False
    clamp: bool = True
    directional_specular_map: bool = False


def offset_count(effects: Effects) -> float:
    """Return how often the colour transform's offset enters a pixel: 2 with specular, else 1.

    The transform is affine and AlbedoMM applies it to the diffuse and the
    specular image separately, so ``T(D) + T(S) = T_linear(D + S) + 2 offset``.
    """
    return 2.0 if effects.specular else 1.0


def effects_for(
    params: RenderParameter,
    has_specular: bool,
    *,
    specular: bool = True,
    shadows: bool = False,
    gamma: bool = False,
    clamp: bool = True,
    directional_specular_map: bool = False,
) -> Effects:
    """Return the effect set a scene needs.

    Specular is on iff the model has a specular part, the caller asks for it and
    the SH light is non-empty (AlbedoMM's specular reuses the SH light);
    directional iff ``params.directional_light.enabled``; shadows only with a
    directional light; colour transform iff it is not the identity;
    ``directional_specular_map`` only with a directional light and a specular part.

    Notes
    -----
    scalismo uses the directional light only when the SH light is empty; here both
    are summed when both are set (the default directional light is off).
    """
    k = min(int(params.environment_map.coefficients.shape[0]), MAX_SH_COEFFICIENTS)
    directional = bool(params.directional_light.enabled)
    return Effects(
        sh_coefficients=k,
        specular=bool(has_specular and specular and k > 0),
        directional=directional,
        shadows=bool(shadows and directional),
        color_transform=not params.color_transform.is_identity,
        gamma=bool(gamma),
        clamp=bool(clamp),
        directional_specular_map=bool(directional_specular_map and directional and has_specular),
    )
