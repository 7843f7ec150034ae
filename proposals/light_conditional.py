"""The SH light's exact Gaussian conditional: a Gibbs draw of all 27 light coefficients.

With geometry, pose, camera, albedo, colour transform and specular exponent
fixed, a rendered face pixel is affine in the SH light ``L`` (K, 3):
``R_pc = sum_d M_cd sum_i G_pdi L_id + o_c`` with ``G_pdi = rho_pd B_pi + s_pd S_pi``
(diffuse albedo times Lambert transport plus specular albedo times the lobe's
transport; :mod:`albedo_model.render.light_basis`), ``M``, ``o`` the colour
transform. With Gaussian pixel noise of sd ``sigma`` and the independent
Gaussian prior ``L_id ~ N(mu_id, tau_id^2)``, the conditional of ``vec L`` is
Gaussian with precision ``diag(1 / tau^2) + A^T A / sigma^2`` and mean
``Lambda^-1 (mu / tau^2 + A^T (t - o) / sigma^2)``. It is exact up to the clamp
at 1 (pixels rendered at or above the saturation limit under the current light
are left out) and the face mask, which does not depend on the light.

:class:`LightConditional` draws ``L' ~ N(m, Lambda^-1)``: an independence
proposal whose mean and precision do not depend on ``L``, so the exact ratio is
``log N(L; m, Lambda^-1) - log N(L'; m, Lambda^-1)``; the kernel's joint MH test
corrects what the clamp leaves. With a directional light whose highlight has the
colour of its diffuse term (the fit's), the render is affine in its RGB
strength too: :class:`LightSystem` ``directional`` adds it as a (K+1)-th row of
``L`` and the move draws both (touching ``Block.LIGHT | Block.DIRECTIONAL_STRENGTH``:
the direction, and so the cast shadows, stay).

:class:`ContrastLightExchange` steps the colour contrast and redraws the
light from this conditional under the new colour matrix
(:func:`with_matrix`): the contrast scales the chroma of every rendered colour
and so does the light's colour, and along that ridge the light's conditional
(contrast held) and a contrast step (light held) each move a little. On the
evaluation's held-out `ambient` subject 62 one chain sat for 1,750 kept
steps at contrast 0.16 with a light lacking blue, where the other held 0.69,
every whitened move refused. It is the light's counterpart of
:class:`~proposals.albedo_offset.ContrastAlbedoExchange`.

This module imports only :mod:`albedo_model.params`, :mod:`albedo_model.render.cache_table`
and :mod:`proposals` (albedo_solver, base).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import ClassVar, NamedTuple

import numpy as np

from albedo_model.params import Block, SHLight
from albedo_model.render.cache_table import Kept
from proposals.albedo_solver import independence_draw
from proposals.base import Move, ProposalState, check_scale, no_move

__all__ = ["STRENGTH_PROPOSAL", "ContrastLightExchange", "LightConditional", "LightSystem",
           "LightSystemData", "conditional", "light_system", "prior_of", "with_matrix"]

#: ``(mean, sd)`` of the Gaussian that stands in for the directional strength's prior in
#: the proposal (the MH test applies the true log-normal prior; a draw <= 0 is rejected).
STRENGTH_PROPOSAL = (0.5, 1.0)


class LightSystem(NamedTuple):
    """The render at N face pixels as an affine function of ``vec L`` (index ``3 i + d``).

    Attributes
    ----------
    gram : (3K, 3K) float64
        ``A^T A`` over the pixels.
    rhs : (3K,) float64
        ``A^T (t - o)``.
    n_pixels : int
    key : tuple or None
        Version stamps of the blocks it reads (the factorisation is kept while unchanged).
    directional : bool
        The last 3 unknowns are the directional light's RGB strength (its
        transport a (K+1)-th row of ``L``), drawn with the SH light.
    transport : (3, 3, K, K) float64 or None
        ``sum_p G_pdi G_pej``, and
    cross : (3, 3, K) float64 or None
        ``sum_p (t_pc - o_c) G_pdi``: with both, :func:`with_matrix` forms the
        system under any other colour matrix. None where the target itself
        depends on the matrix (a directional light held as an offset).
    """

    gram: np.ndarray
    rhs: np.ndarray
    n_pixels: int
    key: tuple | None = None
    directional: bool = False
    transport: np.ndarray | None = None
    cross: np.ndarray | None = None


def light_system(g: np.ndarray, mat: np.ndarray, target_minus_offset: np.ndarray,
                 key: tuple | None = None, directional: bool = False, *,
                 matrix_free_target: bool = True) -> LightSystem:
    """Normal-equation terms from per-pixel transport.

    Parameters
    ----------
    g : (N, 3, K) float array
        ``G_pdi``: albedo times transport of each SH coefficient, per albedo channel d.
    mat : (3, 3) float array
        Colour-transform matrix ``M`` (output channel c from channel d: ``M_cd``).
    target_minus_offset : (N, 3) float array
        ``t_pc - o_c``.
    key : tuple, optional
    directional : bool
        ``g``'s last row is the directional light's transport (see :class:`LightSystem`).
    matrix_free_target : bool
        The target does not depend on ``mat`` and the render applies it (False:
        no :func:`with_matrix`).
    """
    g = np.asarray(g, np.float64)
    h = np.einsum("pdi,pej->deij", g, g)  # (3, 3, K, K)
    cross = np.einsum("pc,pdi->cdi", np.asarray(target_minus_offset, np.float64), g)
    system = LightSystem(np.zeros(0), np.zeros(0), int(g.shape[0]), key, directional, h, cross)
    system = with_matrix(system, mat)
    return system if matrix_free_target else system._replace(transport=None, cross=None)


def with_matrix(system: LightSystem, mat: np.ndarray) -> LightSystem:
    """Return ``system`` under the colour matrix ``mat`` (its ``transport`` and ``cross`` kept)."""
    if system.transport is None or system.cross is None:
        raise ValueError("light system: formed for one colour matrix only")
    m = np.asarray(mat, np.float64)
    k = system.transport.shape[2]
    gram = np.einsum("de,deij->idje", m.T @ m, system.transport).reshape(3 * k, 3 * k)
    rhs = np.einsum("cd,cdi->id", m, system.cross).reshape(3 * k)  # sum_p G_pdi (t-o)_p . M_:d
    return system._replace(gram=gram, rhs=rhs)


#: ``data(state) -> LightSystem or None`` of the accepted state.
LightSystemData = Callable[[ProposalState], "LightSystem | None"]


def conditional(system: LightSystem, sigma: float, prior_mean: np.ndarray,
                prior_sd: np.ndarray):
    """Return ``(mean, Cholesky factor of the precision)`` of the light's Gaussian conditional."""
    prec0 = 1.0 / (prior_sd.reshape(-1) ** 2)
    lam = np.diag(prec0) + system.gram / (sigma * sigma)
    chol = np.linalg.cholesky(lam)
    h = prec0 * prior_mean.reshape(-1) + system.rhs / (sigma * sigma)
    mean = np.linalg.solve(chol.T, np.linalg.solve(chol, h))
    return mean, chol


def prior_of(system: LightSystem, prior_mean: np.ndarray, prior_sd: np.ndarray,
             params) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the proposal's prior mean and sd (K or K+1 rows) and the current unknowns."""
    L = np.asarray(params.environment_map.coefficients, np.float64).reshape(-1)
    if not system.directional:
        return prior_mean, prior_sd, L
    light = params.directional_light
    return (np.vstack([prior_mean, np.full((1, 3), STRENGTH_PROPOSAL[0])]),
            np.vstack([prior_sd, np.full((1, 3), STRENGTH_PROPOSAL[1])]),
            np.concatenate([L, np.asarray(light.diffuse, np.float64)]))


def _with_light(params, new: np.ndarray, directional: bool):
    """Return ``params`` with the drawn unknowns ``new`` set, and the blocks that changed."""
    shape = np.shape(params.environment_map.coefficients)
    k = int(np.prod(shape))
    moved = params._replace(environment_map=SHLight(new[:k].reshape(shape)))
    if not directional:
        return moved, Block.LIGHT
    strength = tuple(float(v) for v in new[k:])
    light = params.directional_light
    return (moved._replace(directional_light=light._replace(diffuse=strength, specular=strength)),
            Block.LIGHT | Block.DIRECTIONAL_STRENGTH)


@dataclass(eq=False)
class LightConditional:
    """Independence proposal ``vec L' ~ N(m, Lambda^-1)`` from the light's Gaussian conditional.

    Parameters
    ----------
    data : LightSystemData
    prior_mean, prior_sd : (K, 3) float arrays
        The Gaussian prior of the SH light.
    sigma : float
        Effective pixel noise of the likelihood (sigma x sqrt(temperature)).
    name : str
    """

    data: LightSystemData
    prior_mean: np.ndarray
    prior_sd: np.ndarray
    sigma: float = 0.043
    name: str = "light-conditional"
    touches: ClassVar[Block] = Block.LIGHT | Block.DIRECTIONAL_STRENGTH
    _factorisation: Kept = field(default_factory=Kept, repr=False)

    def __post_init__(self) -> None:
        """Validate ``sigma`` and the prior."""
        check_scale(self.sigma, "light conditional sigma")
        self.prior_mean = np.asarray(self.prior_mean, np.float64)
        self.prior_sd = np.asarray(self.prior_sd, np.float64)
        if self.prior_mean.shape != self.prior_sd.shape or np.any(self.prior_sd <= 0):
            raise ValueError("light conditional: prior mean and sd must match, sd > 0")

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        params = state.params
        L = np.asarray(params.environment_map.coefficients, np.float64)
        z = rng.normal(0.0, 1.0, L.size)
        if L.shape != self.prior_mean.shape:
            return no_move(params, self.name)
        system = self.data(state)
        if system is None or system.n_pixels == 0:
            return no_move(params, self.name)
        mean, sd, x = prior_of(system, self.prior_mean, self.prior_sd, params)
        if system.directional:  # the SH light and the directional strength together
            z = np.concatenate([z, rng.normal(0.0, 1.0, 3)])
        new, ratio = independence_draw(x, z, self._here(system, mean, sd))
        moved, touched = _with_light(params, new, system.directional)
        return Move(moved, ratio, touched, self.name, joint=True)

    def _here(self, system: LightSystem, mean: np.ndarray, sd: np.ndarray):
        """Return the conditional of the accepted state's system (kept while its key holds)."""
        return self._factorisation.get(system.key, lambda: conditional(
            system, self.sigma, mean, sd))


@dataclass(eq=False)
class ContrastLightExchange(LightConditional):
    """Step the colour contrast, redraw the SH light from its conditional under it.

    Parameters
    ----------
    data : LightSystemData
        The light system of the accepted state (its render, its colour matrix).
    prior_mean, prior_sd : (K, 3) float arrays
        The Gaussian prior of the SH light.
    sigma : float
        The likelihood's effective pixel sd.
    name : str
    step : float
        Sd of the contrast's Gaussian step.

    Notes
    -----
    Forward: ``kappa' = kappa + N(0, step^2)`` (symmetric; ``kappa' <= 0`` is
    refused, as is a state with ``kappa <= 0``: the refusal is symmetric in the
    pair), ``L' ~ N(m(kappa'), Lambda(kappa')^-1)``; backward the same from
    ``kappa'``. Ratio: ``log N(L; m(kappa), Lambda(kappa)^-1) - log N(L';
    m(kappa'), Lambda(kappa')^-1)``; the kernel's MH test with the exact
    posterior corrects the clamp the conditional leaves out. Where the model
    is linear the acceptance is the ratio of ``kappa``'s marginal posterior
    with the light integrated out.
    """

    name: str = "contrast-light-exchange"
    step: float = 0.1
    touches: ClassVar[Block] = (Block.LIGHT | Block.DIRECTIONAL_STRENGTH
                                | Block.COLOR_TRANSFORM)

    def __post_init__(self) -> None:
        """Validate the scales and the prior."""
        super().__post_init__()
        check_scale(self.step, "contrast-light exchange step")

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        params = state.params
        ct = params.color_transform
        L = np.asarray(params.environment_map.coefficients, np.float64)
        kappa = float(ct.contrast) + rng.normal(0.0, self.step)
        z = rng.normal(0.0, 1.0, L.size + 3)
        if L.shape != self.prior_mean.shape or not (ct.contrast > 0 and kappa > 0):
            return no_move(params, self.name)
        system = self.data(state)
        if system is None or system.n_pixels == 0 or system.transport is None:
            return no_move(params, self.name)
        mean, sd, x = prior_of(system, self.prior_mean, self.prior_sd, params)
        z = z if system.directional else z[:L.size]
        new_ct = ct._replace(contrast=kappa)
        there = conditional(with_matrix(system, new_ct.matrix()), self.sigma, mean, sd)
        new, ratio = independence_draw(x, z, there, self._here(system, mean, sd))
        moved, touched = _with_light(params, new, system.directional)
        return Move(moved._replace(color_transform=new_ct), ratio,
                    touched | Block.COLOR_TRANSFORM, self.name, joint=True)
