"""The scene scalars the shader reads (:class:`ShadingParams`), as a pytree or one packed vector.

:func:`pack_shading_params` writes them into one float32 host vector, so that a
jitted shader gets them with a single host-to-device copy (twelve small
``device_put`` calls cost about 0.5 ms per step); :func:`unpack_shading_params`
recovers the pytree inside the ``jit``.

This module imports only :mod:`albedo_model.params` and :mod:`albedo_model.sh`.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import numpy as np

from albedo_model.params import RenderParameter
from albedo_model.sh import MAX_SH_COEFFICIENTS

__all__ = ["ShadingParams", "PACKED_SIZE", "pack_shading_params", "packed_slice",
           "unpack_shading_params", "shading_params"]


class ShadingParams(NamedTuple):
    """Scene scalars of the shading, as a pytree of float32 arrays (traced, never static).

    Attributes
    ----------
    rotation : (3, 3) world-from-object rotation of the pose (normals are rotated
        and renormalised, so a positive scale factor is harmless).
    sh : (9, 3) radiance map in scalismo's order, zero-padded to 9 rows (world frame).
    specular_exponent : () AlbedoMM exponent e.
    light_direction : (3,) direction towards the directional light (world frame).
    light_ambient, light_diffuse, light_specular : (3,) RGB.
    light_shininess : () Blinn-Phong exponent.
    color_gain : (3,), color_contrast : (), color_offset : (3,)
    background : (3,) RGB written where no surface is hit (output space).
    """

    rotation: jax.Array
    sh: jax.Array
    specular_exponent: jax.Array
    light_direction: jax.Array
    light_ambient: jax.Array
    light_diffuse: jax.Array
    light_specular: jax.Array
    light_shininess: jax.Array
    color_gain: jax.Array
    color_contrast: jax.Array
    color_offset: jax.Array
    background: jax.Array


_SHAPES = {
    "rotation": (3, 3), "sh": (MAX_SH_COEFFICIENTS, 3), "specular_exponent": (),
    "light_direction": (3,), "light_ambient": (3,), "light_diffuse": (3,),
    "light_specular": (3,), "light_shininess": (), "color_gain": (3,), "color_contrast": (),
    "color_offset": (3,), "background": (3,),
}
_SLICES: dict[str, slice] = {}
_start = 0
for _name in ShadingParams._fields:
    _n = int(np.prod(_SHAPES[_name], dtype=int))
    _SLICES[_name] = slice(_start, _start + _n)
    _start += _n
#: Length of a packed :class:`ShadingParams` vector.
PACKED_SIZE = _start
del _start, _name, _n


def packed_slice(name: str) -> slice:
    """Return the slice of field ``name`` (a :class:`ShadingParams` field) in a packed vector."""
    return _SLICES[name]


def pack_shading_params(
    params: RenderParameter, rotation: np.ndarray, *, background=(0.0, 0.0, 0.0)
) -> np.ndarray:
    """Pack the scene scalars of the shading into one host float32 vector.

    :func:`unpack_shading_params` is the inverse.

    Parameters
    ----------
    params : RenderParameter
    rotation : (3, 3) float array
        World-from-object rotation of ``params.pose`` (``Rz(roll) Ry(yaw) Rx(pitch)``).
    background : (3,) float
        Output colour of pixels without a hit.

    Returns
    -------
    (PACKED_SIZE,) float32, fields in :class:`ShadingParams` order, SH zero-padded to 9 rows.
    """
    coeffs = np.asarray(params.environment_map.coefficients, np.float64)
    if coeffs.ndim != 2 or coeffs.shape[1] != 3:
        raise ValueError(f"SH coefficients must have shape (K, 3), got {coeffs.shape}")
    k = min(coeffs.shape[0], MAX_SH_COEFFICIENTS)
    dl = params.directional_light
    ct = params.color_transform
    out = np.zeros(PACKED_SIZE, np.float32)
    out[_SLICES["rotation"]] = np.asarray(rotation, np.float64).reshape(9)
    out[_SLICES["sh"]][: 3 * k] = coeffs[:k].reshape(-1)
    for name, value in (("specular_exponent", params.specular_exponent),
                        ("light_direction", dl.direction), ("light_ambient", dl.ambient),
                        ("light_diffuse", dl.diffuse), ("light_specular", dl.specular),
                        ("light_shininess", dl.shininess), ("color_gain", ct.gain),
                        ("color_contrast", ct.contrast), ("color_offset", ct.offset),
                        ("background", background)):
        out[_SLICES[name]] = np.asarray(value, np.float64).reshape(-1)
    return out


def unpack_shading_params(packed: jax.Array) -> ShadingParams:
    """:class:`ShadingParams` views of a :func:`pack_shading_params` vector (use inside ``jit``)."""
    return ShadingParams(**{name: packed[sl].reshape(_SHAPES[name])
                            for name, sl in _SLICES.items()})


def shading_params(
    params: RenderParameter, rotation: np.ndarray, *, background=(0.0, 0.0, 0.0)
) -> ShadingParams:
    """Device-resident :class:`ShadingParams` from a scene.

    Parameters
    ----------
    params : RenderParameter
    rotation : (3, 3) float array
        World-from-object rotation of ``params.pose`` (``Rz(roll) Ry(yaw) Rx(pitch)``).
    background : (3,) float
        Output colour of pixels without a hit.
    """
    packed = pack_shading_params(params, rotation, background=background)
    leaves = {name: packed[sl].reshape(_SHAPES[name]) for name, sl in _SLICES.items()}
    return ShadingParams(**jax.device_put(leaves))
