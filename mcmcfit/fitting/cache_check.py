"""``--check-cache``: every cached product of a chain compared with a fresh computation, each step.

A debug mode for the one cache table (:mod:`albedo_model.render.cache_table`).
After every step, the accepted state's caches are checked:

* its render (shape and albedo instances, effect set, packed shading scalars,
  the shaded image and face mask) against a full render of its parameters by
  a second, independent :class:`~albedo_model.render.renderer.Renderer`;
* its log densities (prior, landmark factor, image likelihood) against fresh
  evaluations (the sampler skips the landmark factor when a move touched none
  of its blocks);
* the data of the data-driven proposals (the albedo conditional's system, the
  SH solver's points) against data recomputed from scratch, from the same render.

Instances and images are compared with float32 tolerances (block updates of
the instances accumulate in float32). A silhouette pixel may flip between hit
and miss when an instance differs in its last bits: up to :data:`EDGE_PIXELS`
such pixels are allowed (and the image likelihood is then not compared). The
proposal data must be identical.

This module imports :mod:`albedo_model` (errors, render.renderer, render.state),
:mod:`proposals.base`, :mod:`mcmcfit.sampling.kernel` and :mod:`mcmcfit.targets.face`.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence

import numpy as np

from albedo_model.errors import AlbedoModelError
from albedo_model.render.cache_table import Kept
from albedo_model.render.renderer import Renderer
from albedo_model.render.state import RenderState
from mcmcfit.sampling.kernel import ChainState, StepInfo
from mcmcfit.targets.face import FaceTarget
from proposals.base import ProposalState

__all__ = ["EDGE_PIXELS", "CacheCheck", "CacheMismatchError"]

#: Pixels allowed to differ beyond the tolerance (hit/miss flips at the silhouette).
EDGE_PIXELS = 3
_IMAGE_ATOL = 2e-3
_INSTANCE_ATOL = 1e-3  # mm and albedo units
_LOG_RTOL = 1e-5
#: Float32 rounding of a rendered pixel value: the chain's incrementally updated instances
#: and a fresh render differ by up to ~3e-7 (measured) where nothing is stale.
_PIXEL_EPS = 1e-6


class CacheMismatchError(AlbedoModelError):
    """A cached product differs from a fresh computation (a dependency missing from the table)."""


def _uncached(data):
    """Return a copy of a proposal-data object without its kept values (computes from scratch)."""
    fresh = copy.copy(data)
    for name, value in vars(data).items():
        if isinstance(value, Kept):
            setattr(fresh, name, Kept())
    return fresh


def _same(a, b) -> bool:
    """Exact equality of nested tuples / arrays / scalars (None allowed)."""
    if a is None or b is None:
        return a is None and b is None
    if isinstance(a, tuple) and not hasattr(a, "_fields") or isinstance(a, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if hasattr(a, "_fields"):  # NamedTuple
        return all(_same(getattr(a, f), getattr(b, f)) for f in a._fields)
    return np.array_equal(np.asarray(a), np.asarray(b))


class CacheCheck:
    """The ``callback(i, state, info)`` that checks a chain's caches after each step.

    Parameters
    ----------
    target : FaceTarget
        The chain's target (its renderer holds the chain's caches).
    data : sequence of (name, callable)
        The chain's proposal-data objects (``data(state)``), e.g. the albedo
        conditional's and the SH solver's.
    stage : str
        "landmarks" or "image", for the messages.

    Raises
    ------
    CacheMismatchError
        From ``__call__``, naming the step, the move, the product and the difference.
    """

    def __init__(self, target: FaceTarget, data: Sequence[tuple[str, object]] = (), *,
                 stage: str = "image"):
        self.target = target
        r = target.renderer
        reference = Renderer(r.model, specular=r.specular, gamma=r.gamma, shadows=r.shadows,
                             background=r.background, threads=1,
                             directional_specular_map=r.directional_specular_map,
                             shadow_rays=r.shadow_rays, shadow_spread_deg=r.shadow_spread_deg)
        self.reference = FaceTarget(reference, target.image_likelihood, target.landmarks,
                                    target.prior)
        self.data = tuple(data)
        self.stage = stage
        self.checked = 0

    def _fail(self, i: int, info: StepInfo | None, what: str, detail: str) -> None:
        move = "the initial state" if info is None else (
            f"move {info.proposal!r} (touched {info.touched}, "
            f"{'accepted' if info.accepted else 'not accepted'})")
        raise CacheMismatchError(f"cache check, {self.stage} stage step {i} after {move}: "
                                 f"cached {what} differs from a fresh computation: {detail}")

    def __call__(self, i: int, state: ChainState, info: StepInfo | None = None) -> None:
        """Compare every cached product of ``state`` with a fresh computation."""
        p = state.params
        self._log("log prior", i, info, state.log_prior, self.target.log_prior(p), exact=True)
        self._log("landmark log likelihood", i, info, state.log_lik_lm,
                  self.target.log_lik_landmarks(p))
        rs = state.render_state
        if rs is not None:
            flips = self._render(i, info, rs)
            if flips == 0:
                fresh = self.reference.init_render(p)
                value = self.reference.log_lik_image(fresh)
                self._log("image log likelihood", i, info, state.log_lik_img, value,
                          atol=self._rounding(value, fresh))
            for name, data in self.data:
                cached = data(state)
                recomputed = _uncached(data)(ProposalState(p, rs))
                if not _same(cached, recomputed):
                    self._fail(i, info, f"{name} data", "not identical to data recomputed "
                               "from the same render")
        self.checked += 1

    def _log(self, what: str, i: int, info, cached: float, fresh: float, *,
             exact: bool = False, atol: float = 0.0) -> None:
        if cached == fresh or (math.isinf(cached) and cached == fresh):
            return
        tol = 0.0 if exact else _LOG_RTOL * max(1.0, abs(fresh)) + atol
        if not (abs(cached - fresh) <= tol):
            self._fail(i, info, what, f"{cached!r} vs {fresh!r}")

    def _rounding(self, value: float, fresh: RenderState) -> float:
        """Return how far the image log likelihood may move when every pixel moves by rounding.

        Images that agree to :data:`_PIXEL_EPS` per channel give log likelihoods
        that agree to ``eps sum |r| / (sigma^2 T) <= eps sqrt(2 n |L| / (sigma^2 T))``
        (Cauchy-Schwarz over the ``n`` face channels, ``|L| >= sum r^2 / (2 sigma^2 T)``):
        with a sharp likelihood (a noise-free synthetic image, sigma 0.002) that
        is far above a relative 1e-5 of the value, and a stale cache far above it.
        """
        lik = self.target.image_likelihood
        n = 3 * int(np.count_nonzero(np.asarray(fresh.hits.prim_id) >= 0))
        scale = float(np.min(lik.sigma)) ** 2 * float(lik.temperature)
        if not (math.isfinite(value) and scale > 0):
            return 0.0
        return _PIXEL_EPS * math.sqrt(2.0 * n * abs(value) / scale)

    def _render(self, i: int, info, rs: RenderState) -> int:
        """Compare the render with a fresh one; return the number of silhouette flips."""
        ref = self.reference.renderer
        fresh = ref.init_state(rs.params)
        for what, a, b in (("shape instance", rs.shape, fresh.shape),
                           ("albedo instance", rs.albedo, fresh.albedo)):
            a, b = np.asarray(a), np.asarray(b)
            if a.shape != b.shape or not np.allclose(a, b, rtol=0.0, atol=_INSTANCE_ATOL):
                self._fail(i, info, what, f"max |difference| {np.max(np.abs(a - b)):.3g}"
                           if a.shape == b.shape else f"shape {a.shape} vs {b.shape}")
        if rs.effects != fresh.effects:
            self._fail(i, info, "effect set", f"{rs.effects} vs {fresh.effects}")
        if not np.array_equal(rs.shading, fresh.shading):
            self._fail(i, info, "shading scalars", "packed parameters differ")
        mine, theirs = self.target.renderer.image(rs), ref.image(fresh)
        bad = np.any(np.abs(mine.image - theirs.image) > _IMAGE_ATOL, axis=-1) | (
            mine.mask != theirs.mask)
        n_bad = int(bad.sum())
        if n_bad > EDGE_PIXELS:
            diff = float(np.max(np.abs(mine.image - theirs.image)))
            self._fail(i, info, "image", f"{n_bad} pixels differ by more than {_IMAGE_ATOL} "
                       f"(max {diff:.3g}; face {int(theirs.mask.sum())} pixels)")
        return n_bad
