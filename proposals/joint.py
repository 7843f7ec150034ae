"""Several photographs of one face: a joint state, single-image moves lifted to it, a shared conditional.

A joint fit of N images has one identity and N scenes: the shape and albedo
coefficients (:data:`SHARED`) are common to all images; pose, camera,
expression, light, colour transform and specular exponent are each image's own.
:class:`JointParameter` holds one full :class:`~albedo_model.params.RenderParameter`
per image whose shared fields are the *same arrays* in every image, so that
each image keeps its own renderer and caches unchanged.

* :class:`ForImage` applies any single-image proposal to image ``i`` (:func:`lift`
  a whole schedule, leaf by leaf); when
  the move changes a shared block the new values are copied into every image.
  The map from image ``i``'s parameters to the joint state is one-to-one with
  the other images' own fields held, so the inner proposal's ``log_q_ratio``
  is the joint one.
* :class:`SharedAlbedoConditional` draws the shared albedo coefficients from
  their Gaussian conditional given every image's geometry, light and colour
  transform: the images' pixel noises are independent, so their normal
  equations add (:func:`proposals.albedo_solver.conditional_terms`).

This module imports :mod:`albedo_model.params`, :mod:`albedo_model.render.cache_table`,
:mod:`proposals.base` and :mod:`proposals.albedo_solver`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar, NamedTuple

import numpy as np

from albedo_model.errors import InputError
from albedo_model.params import Block, RenderParameter
from albedo_model.render.cache_table import Kept
from proposals.albedo_solver import (
    AlbedoData,
    conditional_terms,
    independence_draw,
    solve_conditional,
)
from proposals.base import (
    Mixture,
    Move,
    Proposal,
    ProposalState,
    check_scale,
    mixture,
    no_move,
)

__all__ = ["SHARED", "ForImage", "JointParameter", "SharedAlbedoConditional", "image_state",
           "lift"]

#: The blocks every image of a joint fit shares: the identity.
SHARED = Block.SHAPE | Block.ALBEDO


class JointParameter(NamedTuple):
    """The state of a joint fit: one scene per image, the identity shared.

    Attributes
    ----------
    images : tuple of RenderParameter
        Image ``i``'s scene; ``momo.shape`` and ``momo.albedo`` are the same
        arrays in every image (:meth:`share` makes them so).
    """

    images: tuple[RenderParameter, ...]

    @classmethod
    def share(cls, images: Sequence[RenderParameter], source: int = 0) -> JointParameter:
        """Join per-image scenes, giving every image the identity of image ``source``."""
        if not len(images):
            raise InputError("a joint state needs at least one image")
        momo = images[source].momo
        return cls(tuple(p._replace(momo=p.momo._replace(shape=momo.shape, albedo=momo.albedo))
                         for p in images))

    @property
    def n_images(self) -> int:
        """Number of images."""
        return len(self.images)

    def with_image(self, i: int, params: RenderParameter, touched: Block) -> JointParameter:
        """Replace image ``i``'s scene; shared blocks in ``touched`` are copied to every image."""
        shape, albedo = params.momo.shape, params.momo.albedo
        out = []
        for j, p in enumerate(self.images):
            if j == i:
                out.append(params)
            elif touched & SHARED:
                momo = p.momo._replace(shape=shape if touched & Block.SHAPE else p.momo.shape,
                                       albedo=albedo if touched & Block.ALBEDO else p.momo.albedo)
                out.append(p._replace(momo=momo))
            else:
                out.append(p)
        return JointParameter(tuple(out))


def image_state(state: Any, i: int) -> ProposalState:
    """Image ``i``'s view of a joint chain state: its scene and its render (or None)."""
    rs = state.render_state
    return ProposalState(state.params.images[i], None if rs is None else rs.states[i])


@dataclass(eq=False)
class ForImage:
    """A single-image proposal applied to image ``image`` of a joint state.

    Parameters
    ----------
    image : int
    proposal : Proposal
        Reads image ``image``'s scene and render; its move is that image's.
    """

    image: int
    proposal: Proposal
    name: str = ""
    touches: Block = Block.NONE

    def __post_init__(self) -> None:
        """Name the lifted proposal ``<name>@<image>`` and copy its blocks."""
        self.name = self.name or f"{self.proposal.name}@{self.image}"
        self.touches = self.proposal.touches

    def __call__(self, rng: np.random.Generator, state: Any) -> Move:
        """Draw a move from the accepted joint ``state`` (not modified) with ``rng``."""
        joint = state.params
        move = self.proposal(rng, image_state(state, self.image))
        if move.touched == Block.NONE:
            return no_move(joint, self.name)
        return Move(joint.with_image(self.image, move.params, move.touched), move.log_q_ratio,
                    move.touched, f"{move.name}@{self.image}", move.joint)


def lift(image: int, proposal: Proposal) -> Proposal:
    """Lift a single-image proposal to image ``image``, leaf by leaf (mixtures kept as mixtures).

    The leaves of the result are :class:`ForImage` wrappers named ``<leaf>@<image>``
    with their leaf's blocks, so that per-leaf statistics and step-size families
    work as for the single-image schedule.
    """
    if isinstance(proposal, Mixture):
        return mixture(*((float(w), lift(image, c))
                         for w, c in zip(proposal.weights, proposal.components)),
                       name=f"{proposal.name}@{image}")
    return ForImage(image, proposal)


@dataclass(eq=False)
class SharedAlbedoConditional:
    """Independence draw of the shared albedo from its conditional given every image.

    Parameters
    ----------
    data : sequence of AlbedoData
        Per image, its albedo system at the accepted state (None: the image adds nothing).
    sigma : sequence of float
        Per image, the pixel noise of its likelihood.
    name : str

    Notes
    -----
    With geometry, light and colour transform fixed in every image, each
    image's render is affine in the shared coefficients and the noises are
    independent, so the conditional precision is ``I + sum_i P_i`` and the
    information vector ``sum_i h_i``. Neither depends on the albedo, so the
    forward and the backward draw use the same Gaussian and the exact ratio is
    ``log N(c) - log N(c')`` (as :class:`~proposals.albedo_solver.AlbedoConditional`,
    which this is for one image). The factorisation is kept while every
    image's system key is unchanged.
    """

    data: Sequence[AlbedoData]
    sigma: Sequence[float]
    name: str = "shared-albedo-conditional"
    touches: ClassVar[Block] = Block.ALBEDO
    _factorisation: Kept = field(default_factory=Kept, repr=False)

    def __post_init__(self) -> None:
        """Validate the per-image noises."""
        if len(self.data) != len(self.sigma) or not len(self.data):
            raise InputError(f"one albedo data source and one sigma per image, got "
                             f"{len(self.data)} and {len(self.sigma)}")
        for s in self.sigma:
            check_scale(s, "shared albedo conditional sigma")

    def conditional(self, state: Any):
        """Return ``(mean (k,), cholesky factor of the precision)`` at a joint state, or None."""
        systems = [(data(image_state(state, i)), s)
                   for i, (data, s) in enumerate(zip(self.data, self.sigma, strict=True))]
        systems = [(sys_, s) for sys_, s in systems if sys_ is not None]
        if not systems:
            return None
        keys = tuple(sys_.key for sys_, _ in systems)
        key = None if any(k is None for k in keys) else keys

        def compute():
            terms = [t for sys_, s in systems if (t := conditional_terms(sys_, 1.0, s)) is not None]
            if not terms:
                return None
            return solve_conditional(sum(t[0] for t in terms), sum(t[1] for t in terms))

        return self._factorisation.get(key, compute)

    def __call__(self, rng: np.random.Generator, state: Any) -> Move:
        """Draw a move from the accepted joint ``state`` (not modified) with ``rng``."""
        joint = state.params
        first = joint.images[0]
        c = np.asarray(first.momo.albedo, np.float64)
        z = rng.normal(0.0, 1.0, c.shape[0])
        cond = self.conditional(state) if c.shape[0] else None
        if cond is None:
            return no_move(joint, self.name)
        new, ratio = independence_draw(c, z, cond)
        moved = first._replace(momo=first.momo._replace(albedo=new))
        return Move(joint.with_image(0, moved, Block.ALBEDO), ratio, Block.ALBEDO, self.name,
                    joint=True)
