"""The posterior of several photographs of one face, as a sampler target.

The images are conditionally independent given the face: the joint posterior
is the prior of the identity (shape and albedo, counted once), each image's
prior of its own scene, and every image's landmark and image likelihoods.
Each image keeps its :class:`~mcmcfit.targets.face.FaceTarget` (its renderer,
likelihoods and caches); a move re-renders only the images whose scene it
changed, and each of those only in the stages its blocks touch (a shared
shape move re-casts every image, a pose move of image 2 re-casts image 2).

For one image the joint target's densities equal its face target's.

This module imports :mod:`albedo_model.params`, :mod:`proposals.joint`,
:mod:`mcmcfit.targets.face` and :mod:`mcmcfit.targets.priors`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, NamedTuple

from albedo_model.errors import InputError
from albedo_model.params import Block
from mcmcfit.targets.face import FaceTarget
from mcmcfit.targets.priors import LogPrior
from proposals.joint import SHARED, JointParameter

__all__ = ["JointRenderState", "JointTarget"]

#: Prior terms of the identity (:meth:`LogPrior.terms`), counted once however many images.
_IDENTITY_TERMS = ("shape", "albedo")


def _blocks_to_render(old, new, touched: Block) -> Block:
    """``touched``, or only its shared part when the image's own fields are the same objects."""
    own_kept = all(a is b for a, b in zip(old, new) if a is not old.momo) and (
        new.momo.expression is old.momo.expression)
    return touched & SHARED if own_kept else touched


class JointRenderState(NamedTuple):
    """The renders of a joint state.

    Attributes
    ----------
    params : JointParameter
    states : tuple
        Per image, its face target's render state.
    log_liks : tuple of float
        Per image, its image log likelihood.
    changed : tuple of int
        Images rendered anew for this state (a candidate's pending renders).
    """

    params: JointParameter
    states: tuple[Any, ...]
    log_liks: tuple[float, ...]
    changed: tuple[int, ...] = ()


class JointTarget:
    """Posterior factors of a joint fit (the :class:`~mcmcfit.sampling.kernel.Target` protocol).

    Parameters
    ----------
    faces : sequence of FaceTarget
        One per image, in the order of the joint state's images.
    prior : LogPrior
        The prior of every image's scene and of the shared identity.
    """

    def __init__(self, faces: Sequence[FaceTarget], prior: LogPrior):
        if not len(faces):
            raise InputError("a joint target needs at least one image")
        self.faces = tuple(faces)
        self.prior = prior

    def _check(self, params: JointParameter) -> None:
        if params.n_images != len(self.faces):
            raise InputError(f"the joint state has {params.n_images} images, the target "
                             f"{len(self.faces)}")

    def log_prior(self, params: JointParameter) -> float:
        """Return the log prior: the identity once, every image's own scene."""
        self._check(params)
        terms = list(self.prior.terms(params.images[0]).values())
        for p in params.images[1:]:
            terms += [v for k, v in self.prior.terms(p).items() if k not in _IDENTITY_TERMS]
        v = math.fsum(terms)
        return -math.inf if math.isnan(v) else v

    def log_lik_landmarks(self, params: JointParameter) -> float:
        """Return the sum of the images' landmark (or face-box) log likelihoods."""
        return math.fsum(f.log_lik_landmarks(p) for f, p in zip(self.faces, params.images,
                                                                 strict=True))

    def init_render(self, params: JointParameter) -> JointRenderState:
        """Render every image from scratch; the renders become the accepted ones."""
        self._check(params)
        states = tuple(f.init_render(p) for f, p in zip(self.faces, params.images))
        return JointRenderState(params, states,
                                tuple(f.log_lik_image(s) for f, s in zip(self.faces, states)))

    def render(self, render_state: JointRenderState, params: JointParameter,
               touched: Block) -> JointRenderState:
        """Render the images whose scene differs from the accepted state's."""
        states, liks, changed = list(render_state.states), list(render_state.log_liks), []
        for i, (face, old, new) in enumerate(zip(self.faces, render_state.params.images,
                                                 params.images, strict=True)):
            if new is old:
                continue
            states[i] = face.render(states[i], new, _blocks_to_render(old, new, touched))
            liks[i] = face.log_lik_image(states[i])
            changed.append(i)
        return JointRenderState(params, tuple(states), tuple(liks), tuple(changed))

    def log_lik_image(self, render_state: JointRenderState) -> float:
        """Return the sum of the images' image log likelihoods."""
        return math.fsum(render_state.log_liks)

    def accept(self, render_state: JointRenderState) -> JointRenderState:
        """Keep a candidate: each changed image's render becomes its accepted one."""
        states = list(render_state.states)
        for i in render_state.changed:
            states[i] = self.faces[i].accept(states[i])
        return render_state._replace(states=tuple(states), changed=())

    def reject(self, render_state: JointRenderState) -> None:
        """Drop a candidate: each changed image's renderer keeps its accepted geometry."""
        for i in render_state.changed:
            self.faces[i].reject(render_state.states[i])
