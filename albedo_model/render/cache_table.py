"""The one table of what each cached render product reads: stage -> parameter blocks.

A product is stale after a move exactly when the move touched one of the
blocks of its stage (``STAGE_DEPS[stage] & touched``).

This module imports only :mod:`albedo_model.params`.
"""

from __future__ import annotations

from albedo_model.params import Block

__all__ = ["STAGE_DEPS"]

#: Which touched blocks make each cached stage stale.
STAGE_DEPS = {
    "geometry": Block.SHAPE | Block.EXPRESSION,
    "raycast": Block.SHAPE | Block.EXPRESSION | Block.POSE | Block.CAMERA,
    "albedo": Block.ALBEDO,
    "shading": Block.POSE | Block.LIGHT | Block.COLOR_TRANSFORM | Block.SPECULAR_EXPONENT,
}
