"""Colour-transform proposals: gain (log-normal), contrast and offset (Gaussian); gain x light.

The transform is ``c' = gain * (contrast c + (1 - contrast) Y(c)) + offset``
(:class:`~albedo_model.params.ColorTransform`). The reference's
``GaussianColorProposal`` discards its gain and contrast updates (only the
offset moves); here all three move. :class:`GainLightExchange` moves along
the ridge the image cannot see: a channel's gain times its light.

This module imports only :mod:`albedo_model.errors`, :mod:`albedo_model.params` and
:mod:`proposals.base`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from albedo_model.errors import InputError
from albedo_model.params import Block, SHLight
from proposals.base import Move, ProposalState, check_scale, no_move

__all__ = ["ColorTransformWalk", "GainLightExchange"]


@dataclass(frozen=True)
class ColorTransformWalk:
    """Perturb gain, contrast and offset of the colour transform together.

    Parameters
    ----------
    gain_log_sigma : float
        Each channel's gain ``g_c *= exp(N(0, gain_log_sigma))`` (0: gain kept).
    contrast_sigma : float
        ``contrast += N(0, contrast_sigma)`` (0: kept).
    offset_sigma : float
        Each channel's ``offset_c += N(0, offset_sigma)`` (0: kept).
    name : str, optional (default ``"color-transform-<gain_log_sigma>"``)

    Notes
    -----
    The three parts are independent. Offset and contrast are symmetric walks
    (ratio 0). A gain channel is a log-normal scaling,
    ``q(g'|g) = phi(log(g'/g)) / |g'|``, so its ratio is
    ``log |g'| - log |g| = eps_c`` (valid for either sign of g, g != 0).
    In total ``log_q_ratio = sum_c eps_c``. A channel with zero gain cannot be
    scaled and is left as is (its eps does not count).
    """

    gain_log_sigma: float
    contrast_sigma: float
    offset_sigma: float
    name: str = ""
    touches: ClassVar[Block] = Block.COLOR_TRANSFORM

    def __post_init__(self) -> None:
        """Validate the scales (at least one non-zero) and set a default name."""
        check_scale(self.gain_log_sigma, "gain log sigma", allow_zero=True)
        check_scale(self.contrast_sigma, "contrast sigma", allow_zero=True)
        check_scale(self.offset_sigma, "offset sigma", allow_zero=True)
        if not (self.gain_log_sigma or self.contrast_sigma or self.offset_sigma):
            raise InputError("colour-transform walk needs at least one non-zero sigma")
        if not self.name:
            object.__setattr__(self, "name", f"color-transform-{self.gain_log_sigma:g}")

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        params = state.params
        ct = params.color_transform
        gain = np.asarray(ct.gain, np.float64)
        contrast = float(ct.contrast)
        offset = np.asarray(ct.offset, np.float64)
        ratio = 0.0
        if self.gain_log_sigma:
            eps = rng.normal(0.0, self.gain_log_sigma, 3) * (gain != 0.0)
            gain = gain * np.exp(eps)
            ratio = float(eps.sum())
        if self.contrast_sigma:
            contrast = contrast + float(rng.normal(0.0, self.contrast_sigma))
        if self.offset_sigma:
            offset = offset + rng.normal(0.0, self.offset_sigma, 3)
        new = ct._replace(gain=tuple(float(v) for v in gain), contrast=contrast,
                          offset=tuple(float(v) for v in offset))
        if new == ct:
            return no_move(params, self.name)
        return Move(params._replace(color_transform=new), ratio, Block.COLOR_TRANSFORM, self.name)


@dataclass(frozen=True)
class GainLightExchange:
    """Scale each channel's gain by ``s_c`` and its SH light by ``1 / s_c`` (``log s_c ~ N(0, sigma)``).

    With contrast 1 the render ``g_c (L_c . transport) + offset`` is unchanged
    (exactly; nearly so for contrast near 1), so only the priors of gain and
    light decide: a move along the ridge that separate gain and light walks
    cross only slowly.

    Parameters
    ----------
    log_sigma : float
    name : str, optional (default ``"gain-light-<log_sigma>"``)

    Notes
    -----
    The map is ``(g_c, L_ic) -> (s_c g_c, L_ic / s_c)``; ``log s`` is symmetric,
    so the ratio is the Jacobian ``sum_c (1 - K) log s_c`` (K SH coefficients
    per channel). A zero gain channel is left as is.
    """

    log_sigma: float
    name: str = ""
    touches: ClassVar[Block] = Block.COLOR_TRANSFORM | Block.LIGHT

    def __post_init__(self) -> None:
        """Validate the scale and set a default name."""
        check_scale(self.log_sigma, "gain-light log sigma")
        if not self.name:
            object.__setattr__(self, "name", f"gain-light-{self.log_sigma:g}")

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        params = state.params
        ct = params.color_transform
        gain = np.asarray(ct.gain, np.float64)
        light = np.asarray(params.environment_map.coefficients, np.float64)
        eps = rng.normal(0.0, self.log_sigma, 3) * (gain != 0.0)
        if not np.any(eps) or light.size == 0:
            return no_move(params, self.name)
        k = light.shape[0]
        new_ct = ct._replace(gain=tuple(float(v) for v in gain * np.exp(eps)))
        moved = params._replace(color_transform=new_ct,
                                environment_map=SHLight(light * np.exp(-eps)[None, :]))
        return Move(moved, float((1 - k) * eps.sum()), Block.COLOR_TRANSFORM | Block.LIGHT,
                    self.name)
