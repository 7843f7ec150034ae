"""The proposal interface: :class:`Move`, the :class:`Proposal` protocol and :func:`mixture`.

A proposal is a pure callable ``(rng, state) -> Move`` (emcee's
``propose(model, state)``): ``state`` is the chain's accepted state
(:class:`ProposalState`: the parameters ``state.params`` and, in the image
stage, their render ``state.render_state``). A proposal never mutates it and
draws all randomness from the ``numpy.random.Generator`` it is given. What a
data-driven proposal reads (the SH light solver's points, the albedo
conditional's linear system) is computed from that explicit input, so it
cannot belong to another state than the one the move starts from. It
declares the parameter blocks it may change (``touches``), and each
:class:`Move` reports the blocks it did change (``touched``), so that the
sampler recomputes only the render stages that depend on them (e.g. ray
casting only when pose, camera or geometry moved).

``Block`` -> :class:`~albedo_model.params.RenderParameter` fields:
POSE -> ``pose``; CAMERA -> ``camera``; SHAPE -> ``momo.shape``;
EXPRESSION -> ``momo.expression``; ALBEDO -> ``momo.albedo`` (shared diffuse and
specular coefficients); LIGHT -> ``environment_map``; DIRECTIONAL_ANGLES ->
``directional_light.direction`` (a move of it alone re-casts only the shadow
rays); DIRECTIONAL_STRENGTH -> the rest of ``directional_light`` (casts no ray;
DIRECTIONAL is both); COLOR_TRANSFORM -> ``color_transform``; SPECULAR_EXPONENT -> ``specular_exponent``.
``view`` and ``image_size`` are never proposed.

This module imports only :mod:`albedo_model.errors` and :mod:`albedo_model.params`.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any, NamedTuple, Protocol, runtime_checkable

import numpy as np

from albedo_model.errors import InputError
from albedo_model.params import Block, RenderParameter

__all__ = ["Move", "Proposal", "ProposalState", "Mixture", "mixture", "leaves", "no_move",
           "check_scale"]


class ProposalState(NamedTuple):
    """What a proposal reads: the accepted state of the chain.

    The sampler's own :class:`~mcmcfit.sampling.kernel.ChainState` has the same
    two attributes and is passed as it is; build this one to call a proposal
    directly.

    Attributes
    ----------
    params : RenderParameter
        The accepted parameters x.
    render_state : object or None
        The render of ``params`` (a :class:`~albedo_model.render.state.RenderState`),
        None in the landmark stage.
    """

    params: RenderParameter
    render_state: Any = None


class Move(NamedTuple):
    """A proposed state and what is needed to accept or reject it.

    Attributes
    ----------
    params : RenderParameter
        The proposed state x'.
    log_q_ratio : float
        ``log q(x | x') - log q(x' | x)`` (emcee's convention), densities with
        respect to Lebesgue measure on the parameters as stored in
        ``RenderParameter``. The Metropolis-Hastings log acceptance is
        ``log p(x') - log p(x) + log_q_ratio``.
    touched : Block
        Blocks whose fields differ between x and x' (a subset of the proposal's
        ``touches``; ``Block.NONE`` for a move that changed nothing).
    name : str
        Name of the proposal that produced the move (the chosen leaf of a mixture).
    joint : bool
        Accept with one Metropolis-Hastings test on the whole posterior ratio
        instead of the filter chain. Needed by proposals that draw from an
        approximate conditional (their ``log_q_ratio`` nearly cancels the
        prior and image ratios, so any single filter holding it alone would
        reject almost every move).
    """

    params: RenderParameter
    log_q_ratio: float
    touched: Block
    name: str
    joint: bool = False


@runtime_checkable
class Proposal(Protocol):
    """Anything with ``name``, ``touches`` and ``__call__(rng, state) -> Move``."""

    name: str
    touches: Block

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        ...


def no_move(params: RenderParameter, name: str) -> Move:
    """Return the identity move (x' = x, ratio 0), for a proposal with nothing to move.

    Returning the current state is a valid kernel when the condition that
    triggers it depends only on coordinates the proposal does not change (an
    empty coefficient vector, an all-zero light): the kernel is then the
    identity on that whole fibre, which is trivially reversible.
    """
    return Move(params, 0.0, Block.NONE, name)


def check_scale(value: float, what: str, *, allow_zero: bool = False) -> float:
    """Validate a proposal scale (finite and > 0, or >= 0 with ``allow_zero``)."""
    v = float(value)
    ok = np.isfinite(v) and (v >= 0.0 if allow_zero else v > 0.0)
    if not ok:
        bound = ">= 0" if allow_zero else "> 0"
        raise InputError(f"{what} must be finite and {bound}, got {value!r}")
    return v


@dataclass(frozen=True, eq=False)
class Mixture:
    """Draw one component with fixed probabilities and return its :class:`Move`.

    Build it with :func:`mixture`. ``weights`` are normalised to sum to 1;
    ``touches`` is the union of the components' blocks; the returned move keeps
    the component's (leaf's) name and log ratio.

    Notes
    -----
    **Why the component's ratio is the right one.** The selection probabilities
    do not depend on the state, so one MH step with "draw component i, then
    accept with component i's ratio" is the kernel ``K = sum_i w_i K_i``, where
    each ``K_i`` is a Metropolis-Hastings kernel for the proposal ``q_i`` and is
    therefore reversible with respect to the target. A weighted sum of reversible
    kernels is reversible, so the mixture leaves the target invariant whatever
    its components are (different scales, different families, overlapping or
    disjoint coordinates). This is the standard "random-scan mixture of MH
    kernels" argument; it also holds inside the Metropolis filter chain, where
    each component's filtered kernel is reversible.

    **When it equals the marginal mixture ratio.** The marginal proposal is
    ``q(x'|x) = sum_i w_i q_i(x'|x)``. If every component's ratio is the same
    function of (x, x'), ``q_i(x|x') = r(x, x') q_i(x'|x)`` for all i, then
    ``q(x|x') / q(x'|x) = r(x, x')`` too: the two kernels coincide. This is the
    case for the reference's multi-scale mixtures: symmetric random walks with
    different sigmas (r = 1), log-normal scalings of one coordinate with
    different sigmas (r = x'/x, since q_i(x'|x) = phi_i(log x' - log x) / x'),
    colour-transform walks differing only in their sigmas (r = prod g'/g).
    For components of different families (a yaw walk vs. a focal scaling), the
    components move different coordinates, so for almost every x' only one
    component can produce it and the marginal ratio again reduces to that
    component's ratio; where they overlap, the first argument applies.
    """

    components: tuple
    weights: np.ndarray
    name: str
    touches: Block = field(init=False)
    _cumulative: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        """Derive ``touches`` (the union of the components') and the cumulative weights."""
        touches = Block.NONE
        for c in self.components:
            touches |= c.touches
        object.__setattr__(self, "touches", touches)
        object.__setattr__(self, "_cumulative", np.cumsum(self.weights))

    def choose(self, rng: np.random.Generator) -> int:
        """Index of a component drawn with the normalised weights (one uniform draw)."""
        i = int(np.searchsorted(self._cumulative, rng.random(), side="right"))
        return min(i, len(self.components) - 1)

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        return self.components[self.choose(rng)](rng, state)


def mixture(*weighted: tuple[float, Proposal], name: str = "mixture") -> Mixture:
    """Mix proposals: ``mixture((w1, p1), (w2, p2), ..., name="pose")``.

    Parameters
    ----------
    *weighted : (float, Proposal) pairs
        Non-negative finite weights (normalised here; they need not sum to 1).
        Components of weight 0 are dropped (and do not count in ``touches``).
    name : str
        Name of the mixture itself (moves carry their leaf's name).

    Returns
    -------
    Mixture

    Raises
    ------
    InputError
        No component, a negative or non-finite weight, or all weights zero.
    """
    if not weighted:
        raise InputError("mixture needs at least one (weight, proposal) pair")
    comps, ws = [], []
    for pair in weighted:
        try:
            w, p = pair
        except (TypeError, ValueError) as exc:
            raise InputError(f"mixture expects (weight, proposal) pairs, got {pair!r}") from exc
        w = float(w)
        if not (np.isfinite(w) and w >= 0.0):
            raise InputError(f"mixture weight must be finite and >= 0, got {w!r}")
        if w > 0.0:
            comps.append(p)
            ws.append(w)
    if not comps:
        raise InputError("mixture weights are all zero")
    w = np.asarray(ws, np.float64)
    return Mixture(tuple(comps), w / w.sum(), name)


def leaves(proposal: Proposal, weight: float = 1.0) -> Iterator[tuple[float, Proposal]]:
    """Yield the non-mixture proposals inside ``proposal`` with their overall probabilities.

    Nested mixtures are flattened (probabilities multiply); any other proposal
    (including wrappers such as ``ImageCentered``) is a leaf.

    Yields
    ------
    (probability, proposal) pairs; the probabilities sum to ``weight``.
    """
    if isinstance(proposal, Mixture):
        for w, c in zip(proposal.weights, proposal.components):
            yield from leaves(c, weight * float(w))
    else:
        yield weight, proposal
