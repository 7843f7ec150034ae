"""The one table of what each cached product reads, and the version stamps caches are keyed on.

Every cache of a fit, in the renderer (:mod:`albedo_model.render.renderer`),
in the sampler (the landmark factor) and in the data of the data-driven
proposals (:mod:`mcmcfit.proposal_data`, the albedo conditional of
:mod:`proposals.albedo_solver`), names a row of :data:`STAGE_DEPS`: the
parameter blocks its value is a function of. Nothing else decides when a
cache is stale.

Each render state carries one *version stamp* per parameter block
(:class:`BlockVersions`). A move that touches a block gives it a new stamp,
drawn from one process-wide counter, so two states share a block's stamp only
if one descends from the other without that block being touched: a cache keyed
on ``stage_key(versions, stage)`` is valid exactly when every block of its row
is unchanged, whatever other states were proposed (and rejected) in between.
Stamps are never compared across unrelated states by value; they are not
hashes of the parameters.

==================  ===========================================  =======================
stage               blocks                                       product
==================  ===========================================  =======================
geometry            SHAPE, EXPRESSION                            shape instance, vertex
                                                                 normals, BVH refit
rays                POSE, CAMERA                                 model-frame camera rays
raycast             geometry + rays                              ray hits, pixel set,
                                                                 per-pixel geometry
albedo              ALBEDO                                       albedo instance, per-
                                                                 pixel albedo
effects             LIGHT, DIRECTIONAL, COLOR_TRANSFORM          the effect set
shading             POSE, LIGHT, DIRECTIONAL, COLOR_TRANSFORM,   packed shading scalars
                    SPEC. EXP.
shadow              raycast + DIRECTIONAL_ANGLES                 cast shadows (a shadow ray
                                                                 per face pixel)
light               raycast + LIGHT, DIRECTIONAL, SPEC. EXP.     per-pixel light transport
landmarks           geometry + rays                              landmark log likelihood
albedo_bases        raycast                                      interpolated albedo bases
                                                                 at the face pixels
albedo_system       light + COLOR_TRANSFORM                      the render, linear in the
                                                                 albedo coefficients
light_data          raycast + ALBEDO, COLOR_TRANSFORM            normals, albedo, targets
                                                                 of the SH light solve
light_system        raycast + ALBEDO, COLOR_TRANSFORM,           the render, linear in the
                    SPECULAR_EXPONENT, DIRECTIONAL               SH light (the directional
                                                                 light an offset)
==================  ===========================================  =======================

DIRECTIONAL is the directional light's two blocks, DIRECTIONAL_ANGLES (its
direction) and DIRECTIONAL_STRENGTH: only the cast shadows depend on the
direction alone, so a move of the light's strength (the SH light's exact
conditional, which draws it with the SH light) casts no shadow ray.

This module imports only :mod:`albedo_model.params`.
"""

from __future__ import annotations

import itertools
from typing import NamedTuple

from albedo_model.params import Block

__all__ = ["ATOMIC_BLOCKS", "STAGE_DEPS", "BlockVersions", "Kept", "bump", "new_stamp",
           "new_versions", "stage_key", "stale"]

_GEOMETRY = Block.SHAPE | Block.EXPRESSION
_RAYS = Block.POSE | Block.CAMERA
_DIR = Block.DIRECTIONAL

#: Which parameter blocks each cached product reads (a product is stale after a move
#: that touched any of them).
STAGE_DEPS: dict[str, Block] = {
    "geometry": _GEOMETRY,
    "rays": _RAYS,
    "raycast": _GEOMETRY | _RAYS,
    "albedo": Block.ALBEDO,
    "effects": Block.LIGHT | _DIR | Block.COLOR_TRANSFORM,
    "shading": Block.POSE | Block.LIGHT | _DIR | Block.COLOR_TRANSFORM | Block.SPECULAR_EXPONENT,
    "shadow": _GEOMETRY | _RAYS | Block.DIRECTIONAL_ANGLES,
    "light": _GEOMETRY | _RAYS | Block.LIGHT | _DIR | Block.SPECULAR_EXPONENT,
    "landmarks": _GEOMETRY | _RAYS,
    "albedo_bases": _GEOMETRY | _RAYS,
    "albedo_system": (_GEOMETRY | _RAYS | Block.LIGHT | _DIR | Block.SPECULAR_EXPONENT
                      | Block.COLOR_TRANSFORM),
    "light_data": _GEOMETRY | _RAYS | Block.ALBEDO | Block.COLOR_TRANSFORM,
    "light_system": (_GEOMETRY | _RAYS | Block.ALBEDO | Block.COLOR_TRANSFORM
                     | Block.SPECULAR_EXPONENT | _DIR),
}

#: The single-bit blocks, in :class:`~albedo_model.params.Block` order.
ATOMIC_BLOCKS: tuple[Block, ...] = tuple(b for b in Block if b in Block.ALL)

_STAMPS = itertools.count(1)


def new_stamp() -> int:
    """Return a stamp no state has had before (one process-wide counter)."""
    return next(_STAMPS)


class BlockVersions(NamedTuple):
    """One version stamp per parameter block (in :data:`ATOMIC_BLOCKS` order)."""

    stamps: tuple[int, ...]

    def of(self, blocks: Block) -> tuple[int, ...]:
        """Return the stamps of ``blocks`` (in :data:`ATOMIC_BLOCKS` order)."""
        return tuple(s for b, s in zip(ATOMIC_BLOCKS, self.stamps) if b & blocks)


def new_versions() -> BlockVersions:
    """Return fresh stamps for every block (a state computed from scratch)."""
    return BlockVersions(tuple(new_stamp() for _ in ATOMIC_BLOCKS))


def bump(versions: BlockVersions, touched: Block) -> BlockVersions:
    """Return ``versions`` with a fresh stamp for every block in ``touched``.

    Parameters
    ----------
    versions : BlockVersions
        The stamps of the state a move starts from.
    touched : Block
        The blocks the move changed.

    Returns
    -------
    BlockVersions
    """
    if not touched:
        return versions
    return BlockVersions(tuple(new_stamp() if b & touched else s
                               for b, s in zip(ATOMIC_BLOCKS, versions.stamps)))


def stale(stage: str, touched: Block) -> bool:
    """Return True when a move that touched ``touched`` makes ``stage``'s product stale."""
    return bool(STAGE_DEPS[stage] & touched)


def stage_key(versions: BlockVersions, stage: str) -> tuple[int, ...]:
    """Return the cache key of ``stage``'s product: the stamps of the blocks it reads."""
    return versions.of(STAGE_DEPS[stage])


_NOTHING = object()


class Kept:
    """One product kept while its cache key (e.g. a :func:`stage_key`) is unchanged.

    The caches outside a render state (proposal data, the albedo conditional's
    factorisation) each hold one of these; ``key=None`` means "never reuse".
    """

    __slots__ = ("_key", "_value")

    def __init__(self) -> None:
        self._key, self._value = _NOTHING, None

    def get(self, key, compute):
        """Return the kept value for ``key``, calling ``compute()`` when the key changed."""
        if key is None or self._key is _NOTHING or self._key != key:
            self._key, self._value = key, compute()
        return self._value
