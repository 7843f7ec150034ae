"""The face posterior as a sampler :class:`~mcmcfit.sampling.kernel.Target`: renderer + likelihoods + prior.

Renders with :class:`albedo_model.render.renderer.Renderer` (linear output, as
compared), evaluates :class:`~mcmcfit.targets.image.ImageLikelihood` on the
shader output (fused with the shading in one ``jit`` through
``Renderer.compose`` when the renderer offers it), the landmark (or face-box)
likelihood on the parameters, and the prior. It holds no chain state: the
accepted render lives in the sampler's :class:`~mcmcfit.sampling.kernel.ChainState`
(and reaches the data-driven proposals through it).

This module imports :mod:`albedo_model.params`, :mod:`albedo_model.render.renderer`,
:mod:`mcmcfit.targets.image` and :mod:`mcmcfit.targets.priors`.
"""

from __future__ import annotations

from typing import Protocol

from albedo_model.params import Block, RenderParameter
from albedo_model.render.renderer import Renderer, RenderState
from mcmcfit.targets.image import ImageLikelihood
from mcmcfit.targets.priors import LogPrior

__all__ = ["FaceTarget", "LandmarkFactor"]


class LandmarkFactor(Protocol):
    """Anything with ``log_lik(params) -> float`` (landmarks or a face box)."""

    def log_lik(self, params: RenderParameter) -> float:
        """Return the log likelihood of ``params``."""
        ...


class FaceTarget:
    """Posterior factors of one fit.

    Parameters
    ----------
    renderer : Renderer
        Must render linear colours (``gamma=False``).
    image_likelihood : ImageLikelihood or None
        None for a landmark-only target.
    landmarks : LandmarkFactor or None
    prior : LogPrior
    """

    def __init__(self, renderer: Renderer, image_likelihood: ImageLikelihood | None,
                 landmarks: LandmarkFactor | None, prior: LogPrior):
        if renderer.gamma:
            raise ValueError("FaceTarget compares linear colours: use a Renderer with gamma=False")
        self.renderer = renderer
        self.image_likelihood = image_likelihood
        self.landmarks = landmarks
        self.prior = prior
        self._fused = None
        if image_likelihood is not None and hasattr(renderer, "compose"):
            self._fused = renderer.compose(image_likelihood.pixel_set_fn, pixel_set=True)

    def log_prior(self, params: RenderParameter) -> float:
        """Return the log prior of ``params``."""
        return self.prior(params)

    def log_lik_landmarks(self, params: RenderParameter) -> float:
        """Return the landmark (or face-box) log likelihood of ``params``; 0 without one."""
        return 0.0 if self.landmarks is None else float(self.landmarks.log_lik(params))

    def init_render(self, params: RenderParameter) -> RenderState:
        """Render ``params`` from scratch; its geometry becomes the renderer's accepted one."""
        return self.renderer.init_state(params)

    def render(self, render_state: RenderState, params: RenderParameter,
               touched: Block) -> RenderState:
        """Render ``params`` from ``render_state``, recomputing what ``touched`` makes stale."""
        return self.renderer.update(render_state, params, touched)

    def log_lik_image(self, render_state: RenderState) -> float:
        """Return the image log likelihood of a render state; 0 without an image likelihood."""
        lik = self.image_likelihood
        if lik is None:
            return 0.0
        prim = render_state.prim_id if lik.region is not None else None
        if self._fused is not None:
            return lik.finish(*self._fused(render_state, *lik.device_args()), prim_id=prim)
        return lik(self.renderer.shade(render_state))

    def accept(self, render_state: RenderState) -> RenderState:
        """Keep a candidate render: its geometry becomes the renderer's accepted one."""
        return self.renderer.accept(render_state)

    def reject(self, render_state: RenderState) -> None:
        """Drop a candidate render: the renderer keeps its accepted geometry."""
        self.renderer.reject()
