"""The Metropolis filter chain: one MH step as proposal -> landmarks -> prior -> image.

BlackJAX-style: an immutable :class:`ChainState` carries the log densities of
the current state (never recomputed), :func:`step` is a pure-ish function
``(rng, state, target, proposal) -> (state, info)`` and :func:`run` a plain
Python loop. The only side effects are the target's (the renderer keeps its
double-buffered scenes; see :meth:`Target.accept` / :meth:`Target.reject`).

One step (Schönborn et al. 2017; scalismo's ``MH(Filter_prior(Filter_lm(q)), l_img)``):

1. ``move = proposal(rng, state)`` gives x' and ``log_q_ratio = log q(x|x') - log q(x'|x)``
   (the proposal is handed the accepted state itself: x and, in stage 2, its render);
2. **landmark filter**: accept with ``a1 = l_lm(x') - l_lm(x) + log_q_ratio``;
3. **prior filter**: accept with ``a2 = log p(x') - log p(x)``;
4. **image step** (stage 2 only): render x' (only the stages its ``touched``
   blocks invalidate) and accept with ``a3 = l_img(x') - l_img(x)``.

A rejection at any stage returns x. Moves flagged ``joint`` (proposals drawing
from an approximate conditional, whose ratio nearly cancels the prior and
image ratios) take one plain MH test on the whole ratio instead; their
rejections have their own code (``REJECTED_JOINT``). A move that changes
nothing (``touched`` empty: a proposal with nothing to move) is neither
accepted nor rejected: it is recorded as ``IDENTITY`` and draws no uniform. The rest is
delayed acceptance (Christen & Fox 2005) for the product ``l_lm p l_img``: the
overall acceptance ``min(1, r1) min(1, r2) min(1, r3)`` satisfies detailed balance because
``pi_i(x) min(1, pi_i(x') / pi_i(x)) = min(pi_i(x), pi_i(x'))`` is symmetric
for each factor (the proposal ratio sits in the first one). In stage 1 step 4
is skipped: the chain targets ``l_lm p``.

Acceptance uses one uniform per evaluated stage: accept iff ``log u < a``.
``a`` is ``-inf`` for NaN; a move between two states of log density ``-inf``
in a factor has ratio 0 in that factor (the reference's rule), so a chain
started where nothing renders can still walk until the face appears.

The landmark factor is evaluated only when the move touched a block of
``STAGE_DEPS["landmarks"]`` (:mod:`albedo_model.render.cache_table`).

This module imports only :mod:`albedo_model.params`, :mod:`albedo_model.render.cache_table`
and :mod:`proposals.base`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, NamedTuple, Protocol

import numpy as np

from albedo_model.params import Block, RenderParameter
from albedo_model.render.cache_table import stale
from proposals.base import Proposal

__all__ = [
    "ACCEPTED",
    "IDENTITY",
    "REJECTED_IMAGE",
    "REJECTED_JOINT",
    "REJECTED_LANDMARKS",
    "REJECTED_PRIOR",
    "REJECTION_STAGES",
    "ChainState",
    "StepInfo",
    "Target",
    "init",
    "run",
    "step",
]

ACCEPTED, REJECTED_LANDMARKS, REJECTED_PRIOR, REJECTED_IMAGE, REJECTED_JOINT, IDENTITY = range(6)
#: ``StepInfo.rejected_by`` codes, by name ("identity": the move changed nothing).
REJECTION_STAGES = ("accepted", "landmarks", "prior", "image", "joint", "identity")


class ChainState(NamedTuple):
    """The current sample and its cached log densities.

    Attributes
    ----------
    params : RenderParameter
    log_prior : float
    log_lik_lm : float
        Landmark (or face-box) log likelihood; 0 without landmarks.
    log_lik_img : float
        Image log likelihood; 0 in the landmark stage.
    render_state : object or None
        The target's render cache for ``params`` (None in the landmark stage).
    """

    params: RenderParameter
    log_prior: float
    log_lik_lm: float
    log_lik_img: float
    render_state: Any = None

    @property
    def log_posterior(self) -> float:
        """Unnormalised log posterior ``log p + l_lm + l_img``."""
        return self.log_prior + self.log_lik_lm + self.log_lik_img


class StepInfo(NamedTuple):
    """What happened in one step.

    Attributes
    ----------
    proposal : str
        Name of the proposal leaf that produced the move.
    accepted : bool
        The chain moved to the proposed state (False for an identity move).
    rejected_by : int
        0 accepted, 1 landmark filter, 2 prior filter, 3 image step, 4 the joint
        test of a ``joint`` move, 5 an identity move (:data:`REJECTION_STAGES`).
    log_alpha : float
        Log acceptance ratio of the last stage evaluated.
    touched : Block
        Blocks the move changed.
    """

    proposal: str
    accepted: bool
    rejected_by: int
    log_alpha: float
    touched: Block


class Target(Protocol):
    """The factors of the posterior and the render cache behind the image factor."""

    def log_prior(self, params: RenderParameter) -> float:
        """Log prior density."""
        ...

    def log_lik_landmarks(self, params: RenderParameter) -> float:
        """Landmark log likelihood (0 when there are no landmarks)."""
        ...

    def init_render(self, params: RenderParameter) -> Any:
        """Return a full render state for ``params``; it becomes the accepted one."""
        ...

    def render(self, render_state: Any, params: RenderParameter, touched: Block) -> Any:
        """Return a candidate render state for ``params`` from the accepted one."""
        ...

    def log_lik_image(self, render_state: Any) -> float:
        """Image log likelihood of a render state."""
        ...

    def accept(self, render_state: Any) -> Any:
        """Make a candidate the accepted state; returns it (possibly updated)."""
        ...

    def reject(self, render_state: Any) -> None:
        """Drop a candidate."""
        ...


def _log_ratio(new: float, old: float) -> float:
    if new == old:  # also -inf -> -inf (ratio 0) and +inf -> +inf
        return 0.0
    d = new - old
    return -math.inf if math.isnan(d) else d


def _accept(rng: np.random.Generator, log_alpha: float) -> bool:
    return math.log(rng.random() or 5e-324) < log_alpha


def init(params: RenderParameter, target: Target, *, image: bool = True) -> ChainState:
    """Return the chain state of ``params``: evaluate every factor (render when ``image``)."""
    lp = float(target.log_prior(params))
    lm = float(target.log_lik_landmarks(params))
    if not image:
        return ChainState(params, lp, lm, 0.0, None)
    rs = target.init_render(params)
    return ChainState(params, lp, lm, float(target.log_lik_image(rs)), rs)


def step(rng: np.random.Generator, state: ChainState, target: Target, proposal: Proposal, *,
         image: bool = True) -> tuple[ChainState, StepInfo]:
    """One filtered Metropolis-Hastings step (see the module notes).

    Parameters
    ----------
    rng : numpy Generator
    state : ChainState
        Current state (with ``render_state`` when ``image``).
    target : Target
    proposal : Proposal
    image : bool
        Include the image step (stage 2); False targets ``p l_lm`` (stage 1).

    Returns
    -------
    (ChainState, StepInfo)
    """
    move = proposal(rng, state)
    if move.touched == Block.NONE:
        return state, StepInfo(move.name, False, IDENTITY, 0.0, Block.NONE)
    if move.log_q_ratio == -math.inf or math.isnan(move.log_q_ratio):
        # refused by the proposal itself (a diverged trajectory, a point outside its coordinates)
        stage = REJECTED_JOINT if move.joint else REJECTED_LANDMARKS
        return state, StepInfo(move.name, False, stage, -math.inf, move.touched)
    new = move.params
    if move.joint:
        return _joint_step(rng, state, target, move, image=image)
    if stale("landmarks", move.touched):
        lm = float(target.log_lik_landmarks(new))
    else:
        lm = state.log_lik_lm
    a = _log_ratio(lm, state.log_lik_lm) + float(move.log_q_ratio)
    if math.isnan(a) or not _accept(rng, a):
        return state, StepInfo(move.name, False, REJECTED_LANDMARKS, a, move.touched)
    lp = float(target.log_prior(new))
    a = _log_ratio(lp, state.log_prior)
    if not _accept(rng, a):
        return state, StepInfo(move.name, False, REJECTED_PRIOR, a, move.touched)
    if not image:
        return (ChainState(new, lp, lm, state.log_lik_img, None),
                StepInfo(move.name, True, ACCEPTED, a, move.touched))
    rs = target.render(state.render_state, new, move.touched)
    li = float(target.log_lik_image(rs))
    a = _log_ratio(li, state.log_lik_img)
    if not _accept(rng, a):
        target.reject(rs)
        return state, StepInfo(move.name, False, REJECTED_IMAGE, a, move.touched)
    rs = target.accept(rs)
    return ChainState(new, lp, lm, li, rs), StepInfo(move.name, True, ACCEPTED, a, move.touched)


def _joint_step(rng: np.random.Generator, state: ChainState, target: Target, move, *,
                image: bool) -> tuple[ChainState, StepInfo]:
    """One plain MH step on the whole ratio ``l_lm p l_img`` (for ``move.joint`` proposals)."""
    new = move.params
    lm = float(target.log_lik_landmarks(new)) if stale("landmarks", move.touched) \
        else state.log_lik_lm
    lp = float(target.log_prior(new))
    a = (_log_ratio(lm, state.log_lik_lm) + _log_ratio(lp, state.log_prior)
         + float(move.log_q_ratio))
    if not image:
        if math.isnan(a) or not _accept(rng, a):
            return state, StepInfo(move.name, False, REJECTED_JOINT, a, move.touched)
        return (ChainState(new, lp, lm, state.log_lik_img, None),
                StepInfo(move.name, True, ACCEPTED, a, move.touched))
    if a == -math.inf or math.isnan(a):  # no render can save it: rejected before rendering
        return state, StepInfo(move.name, False, REJECTED_JOINT, a, move.touched)
    rs = target.render(state.render_state, new, move.touched)
    li = float(target.log_lik_image(rs))
    a += _log_ratio(li, state.log_lik_img)
    if math.isnan(a) or not _accept(rng, a):
        target.reject(rs)
        return state, StepInfo(move.name, False, REJECTED_JOINT, a, move.touched)
    rs = target.accept(rs)
    return ChainState(new, lp, lm, li, rs), StepInfo(move.name, True, ACCEPTED, a, move.touched)


def run(rng: np.random.Generator, state: ChainState, target: Target, proposal: Proposal,
        n_steps: int, *, image: bool = True,
        callback: Callable[[int, ChainState, StepInfo], None] | None = None) -> ChainState:
    """``n_steps`` steps of :func:`step`; ``callback(i, state, info)`` after each.

    Returns
    -------
    ChainState
        The final state.
    """
    for i in range(int(n_steps)):
        state, info = step(rng, state, target, proposal, image=image)
        if callback is not None:
            callback(i, state, info)
    return state
