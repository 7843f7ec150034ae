"""Colour-transform proposal: gain (log-normal), contrast and offset (Gaussian).

The transform is ``c' = gain * (contrast c + (1 - contrast) Y(c)) + offset``
(:class:`~albedo_model.params.ColorTransform`). The reference's
``GaussianColorProposal`` discards its gain and contrast updates (only the
offset moves); here all three move.

This module imports only :mod:`albedo_model.errors`, :mod:`albedo_model.params` and
:mod:`proposals.base`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from albedo_model.errors import InputError
from albedo_model.params import Block
from proposals.base import Move, ProposalState, check_scale, no_move

__all__ = ["ColorTransformWalk"]


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
