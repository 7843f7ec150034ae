"""Light proposals on the SH environment map, and the specular-exponent proposal.

The light is ``params.environment_map.coefficients``, L of shape (K, 3) in
scalismo's order (band l holds indices l^2 .. (l+1)^2 - 1); ``n = 3 K`` is the
number of coefficients. The reference's SH proposals (``reference-sampler.md``
§4) are reproduced with exact ratios; the reference returns -inf for the
energy-preserving perturbation, which is a bug (its ratio is 0, see below).

This module imports only :mod:`albedo_model.params` and :mod:`proposals.base`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from albedo_model.params import Block, RenderParameter, SHLight
from proposals.base import Move, ProposalState, check_scale, no_move

__all__ = [
    "SHIntensity", "SHBandMixer", "SHPerturbation", "SHColorShift", "SHSpatial",
    "SpecularExponentScaling",
]


def _light(params: RenderParameter) -> np.ndarray:
    return np.asarray(params.environment_map.coefficients, np.float64)


def _with_light(params: RenderParameter, coefficients: np.ndarray) -> RenderParameter:
    return params._replace(environment_map=SHLight(coefficients))


@dataclass(frozen=True)
class SHIntensity:
    """Scale the whole light: ``L' = s L``, ``s = exp(N(0, log_sigma))``.

    Parameters
    ----------
    log_sigma : float
        Standard deviation of ``log s``. The reference's ``Intensity(sigma)``
        draws ``exp(N(0, 1) sigma / 2)``, i.e. ``log_sigma = sigma / 2``.

    Notes
    -----
    A radial log-normal move in R^n (see :class:`~proposals.coefficients.Caricature`):
    ``log_q_ratio = n log s`` (27 log s for 9 x 3 coefficients). A zero light
    gives the identity move.
    """

    log_sigma: float
    name: str = ""
    touches: ClassVar[Block] = Block.LIGHT

    def __post_init__(self) -> None:
        """Validate the scale and set a default name."""
        check_scale(self.log_sigma, "SH intensity log sigma")
        if not self.name:
            object.__setattr__(self, "name", f"sh-intensity-{self.log_sigma:g}")

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        params = state.params
        L = _light(params)
        log_s = rng.normal(0.0, self.log_sigma)
        if not np.any(L):
            return no_move(params, self.name)
        return Move(_with_light(params, L * np.exp(log_s)), float(L.size * log_s),
                    Block.LIGHT, self.name)


@dataclass(frozen=True)
class SHBandMixer:
    """Scale each band independently: ``L_l' = s_l L_l``, ``s_l = exp(N(0, log_sigma))``.

    Notes
    -----
    A product of radial log-normal moves, one in each band's subspace of
    dimension ``n_l = 3 (2l + 1)``: ``log_q_ratio = sum_l n_l log s_l``. A band
    that is exactly zero cannot be scaled; it is left out (and out of the ratio),
    which is the exact kernel conditional on that band being zero.
    """

    log_sigma: float
    name: str = ""
    touches: ClassVar[Block] = Block.LIGHT

    def __post_init__(self) -> None:
        """Validate the scale and set a default name."""
        check_scale(self.log_sigma, "SH band mixer log sigma")
        if not self.name:
            object.__setattr__(self, "name", f"sh-bands-{self.log_sigma:g}")

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        params = state.params
        L = _light(params)
        k = L.shape[0]
        n_bands = int(np.ceil(np.sqrt(k))) if k else 0
        log_s = rng.normal(0.0, self.log_sigma, n_bands)
        L_new = L.copy()
        ratio = 0.0
        for band in range(n_bands):
            rows = slice(band * band, min((band + 1) * (band + 1), k))
            if np.any(L[rows]):
                L_new[rows] *= np.exp(log_s[band])
                ratio += L[rows].size * log_s[band]
        if ratio == 0.0 and not np.any(L_new != L):
            return no_move(params, self.name)
        return Move(_with_light(params, L_new), float(ratio), Block.LIGHT, self.name)


@dataclass(frozen=True)
class SHPerturbation:
    """Gaussian perturbation of every coefficient, optionally keeping the light's energy.

    Parameters
    ----------
    sigma : float
        ``L + N(0, sigma^2 I_n)``.
    fix_energy : bool
        Rescale the result to the old energy ``||L||^2 = sum_i ||L_i||^2``
        (the reference's ``fixIntensity``, used in its default schedule).

    Notes
    -----
    Without ``fix_energy`` it is a symmetric walk: ratio 0. With it, the move
    stays on the sphere ``||L'|| = ||L|| = R``: the new direction is the
    direction of ``L + eps``, whose density (projected normal) is
    ``int_0^inf t^(n-1) phi_n(t u' - L) dt`` and depends on u' only through
    ``u'.L = R u'.u`` and on ``||L|| = R``, both symmetric in (u, u'). So the
    kernel is symmetric with respect to the surface measure of the sphere; and
    a target ``p(x)`` conditioned on a sphere has density ``p`` there (Lebesgue
    is ``r^(n-1) dr du`` and r is fixed). Hence ``log_q_ratio = 0``; the
    reference's -inf (a condition bug) disables this proposal. A zero light gives
    the identity move.
    """

    sigma: float
    fix_energy: bool = True
    name: str = ""
    touches: ClassVar[Block] = Block.LIGHT

    def __post_init__(self) -> None:
        """Validate the scale and set a default name."""
        check_scale(self.sigma, "SH perturbation sigma")
        if not self.name:
            tag = "sh-perturb-fixed" if self.fix_energy else "sh-perturb"
            object.__setattr__(self, "name", f"{tag}-{self.sigma:g}")

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        params = state.params
        L = _light(params)
        L_new = L + rng.normal(0.0, self.sigma, L.shape)
        if self.fix_energy:
            r, r_new = np.linalg.norm(L), np.linalg.norm(L_new)
            if not (r > 0.0 and r_new > 0.0):
                return no_move(params, self.name)
            L_new *= r / r_new
        return Move(_with_light(params, L_new), 0.0, Block.LIGHT, self.name)


@dataclass(frozen=True)
class SHColorShift:
    """Add one RGB shift to every coefficient, then restore the energy.

    ``L' = c (L + 1 delta)`` with ``delta ~ N(0, sigma^2 I_3)`` added to each row
    L_i and ``c = ||L|| / ||L + 1 delta||``.

    Notes
    -----
    Ratio by the involution ``T(x, delta) = (c (x + 1 delta), -c delta)``
    (x in R^n, delta in R^3): from x' the auxiliary ``-c delta`` leads back to x
    (``||x' - c 1 delta|| = c ||x||``, so the new factor is 1/c). Writing T as
    ``(y, delta) = (x + 1 delta, delta)`` (unit Jacobian) followed by
    ``(y, delta) -> c (y, -delta)`` with c homogeneous of degree 0 in
    (y, delta), the matrix determinant lemma gives ``|det J_T| = c^(n+3)``. The
    involutive MH ratio is therefore
    ``log_q_ratio = log phi(c delta) - log phi(delta) + (n + 3) log c
    = -(c^2 - 1) ||delta||^2 / (2 sigma^2) + (n + 3) log c``.
    The involutive ratio is exact for any state (Green 1995; involutive MCMC).
    Whenever L is not the same colour in every row (always, except on a null
    set, for K >= 2) delta -> x' is one-to-one, and it is also the marginal
    density ratio. The reference reports 0, which is wrong whenever c != 1. A
    zero light gives the identity move.
    """

    sigma: float
    name: str = ""
    touches: ClassVar[Block] = Block.LIGHT

    def __post_init__(self) -> None:
        """Validate the scale and set a default name."""
        check_scale(self.sigma, "SH colour shift sigma")
        if not self.name:
            object.__setattr__(self, "name", f"sh-colour-{self.sigma:g}")

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        params = state.params
        L = _light(params)
        delta = rng.normal(0.0, self.sigma, 3)
        y = L + delta
        r, r_y = np.linalg.norm(L), np.linalg.norm(y)
        if not (r > 0.0 and r_y > 0.0):
            return no_move(params, self.name)
        c = r / r_y
        ratio = -(c * c - 1.0) * float(delta @ delta) / (2.0 * self.sigma**2) \
            + (L.size + 3) * np.log(c)
        return Move(_with_light(params, c * y), float(ratio), Block.LIGHT, self.name)


@dataclass(frozen=True)
class SHSpatial:
    """Monochrome perturbation: ``L_i += eta_i (1, 1, 1)``, ``eta_i ~ N(0, sigma)`` per i.

    Notes
    -----
    A symmetric Gaussian walk in the K-dimensional grey subspace: ratio 0.
    """

    sigma: float
    name: str = ""
    touches: ClassVar[Block] = Block.LIGHT

    def __post_init__(self) -> None:
        """Validate the scale and set a default name."""
        check_scale(self.sigma, "SH spatial sigma")
        if not self.name:
            object.__setattr__(self, "name", f"sh-spatial-{self.sigma:g}")

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        params = state.params
        L = _light(params)
        if L.shape[0] == 0:
            return no_move(params, self.name)
        eta = rng.normal(0.0, self.sigma, (L.shape[0], 1))
        return Move(_with_light(params, L + eta), 0.0, Block.LIGHT, self.name)


@dataclass(frozen=True)
class SpecularExponentScaling:
    """Specular (Phong-like) exponent: ``e' = e exp(N(0, log_sigma))``.

    Notes
    -----
    Log-normal scaling of one positive coordinate: ``log_q_ratio = log e' - log e``.
    The reference keeps e fixed (no proposal); here it is a scene parameter.
    """

    log_sigma: float
    name: str = ""
    touches: ClassVar[Block] = Block.SPECULAR_EXPONENT

    def __post_init__(self) -> None:
        """Validate the scale and set a default name."""
        check_scale(self.log_sigma, "specular exponent log sigma")
        if not self.name:
            object.__setattr__(self, "name", f"specular-exponent-{self.log_sigma:g}")

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        params = state.params
        eps = rng.normal(0.0, self.log_sigma)
        e = float(params.specular_exponent)
        if e == 0.0:
            return no_move(params, self.name)
        return Move(params._replace(specular_exponent=e * float(np.exp(eps))), float(eps),
                    Block.SPECULAR_EXPONENT, self.name)
