"""Image formation of ray-cast pixels in JAX, specialised to the effects a scene calls for.

Modules
-------
effects
    :class:`Effects`: which terms a scene's image formation computes.
scalars
    The scene scalars the shader reads, as a pytree or one packed vector.
interpolation
    Per-pixel attributes of ray-cast hits: normals, view directions, albedo.
image_formation
    Per-pixel light transport, the combination with albedo, colour transform,
    clamp and gamma.
naive
    A deliberately naive shader: the benchmark baseline and the tests' reference.

The package imports :mod:`albedo_model` (params, sh) only, never
:mod:`albedo_model.render`. This file imports :mod:`~albedo_model.shading.effects`
and :mod:`~albedo_model.shading.image_formation`.
"""

from albedo_model.shading.effects import Effects, effects_for
from albedo_model.shading.image_formation import Shaded, shade

__all__ = ["Effects", "Shaded", "effects_for", "shade"]
