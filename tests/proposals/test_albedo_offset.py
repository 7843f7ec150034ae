"""The joint albedo + colour offset conditional against an explicit linear-Gaussian posterior."""

from __future__ import annotations

import numpy as np
import pytest

from mh_chain import DropRatio, check_exchange_moments, grid_moments, run_chain

from albedo_model.params import Block, ColorTransform, MoMoCoefficients, default_square
from proposals.albedo_offset import (
    AlbedoOffsetConditional, ContrastAlbedoExchange, _with_contrast, albedo_offset_conditional,
)
from proposals.albedo_solver import albedo_system
from proposals.base import ProposalState

SIGMA = 0.05
OFFSET_SD = 0.1


def _system(seed: int, n: int = 300, k: int = 5, count: float = 2.0, weighted: bool = False,
            off_now=(0.01, -0.02, 0.03)):
    """A render affine in (c, o) with known truth, its rows stored as RenderAlbedoData does."""
    rng = np.random.default_rng(seed)
    jac = rng.normal(0, 0.1, (n, 3, k))
    mean = rng.uniform(0.1, 0.3, (n, 3))
    photo = (mean + np.einsum("ncj,j->nc", jac, rng.normal(0, 1, k))
             + count * rng.normal(0, OFFSET_SD, 3) + rng.normal(0, SIGMA, (n, 3)))
    off = count * np.asarray(off_now)
    sw = rng.uniform(0.3, 1.0, n) if weighted else None
    if sw is not None:  # rows scaled by the root weights, the target as the data source stores it
        jac, mean = jac * sw[:, None, None], mean * sw[:, None]
        target = (photo - off) * sw[:, None] + off
    else:
        target = photo
    system = albedo_system(jac.astype(np.float32), mean.astype(np.float32),
                           np.full((n, 3), 0.2, np.float32), target.astype(np.float32),
                           off.astype(np.float32), np.arange(n), 10**6, key=("fixed",),
                           offset_count=count, row_weights=sw)
    design = np.zeros((n, 3, k + 3))  # d (weighted residual) / d (c, o)
    design[..., :k] = jac
    for c in range(3):
        design[:, c, k + c] = count * (1.0 if sw is None else sw)
    prec = np.diag(np.r_[np.ones(k), np.full(3, 1 / OFFSET_SD**2)])
    a = design.reshape(-1, k + 3)
    rows = (photo if sw is None else photo * sw[:, None]) - mean
    post_prec = prec + a.T @ a / SIGMA**2
    post_mean = np.linalg.solve(post_prec, a.T @ rows.reshape(-1) / SIGMA**2)
    return system, post_mean, post_prec


def _params(x: np.ndarray, k: int):
    return default_square()._replace(
        momo=MoMoCoefficients(np.zeros(0), np.asarray(x[:k], float), np.zeros(0)),
        color_transform=ColorTransform(offset=tuple(float(v) for v in x[k:])))


def _features(p):
    return np.r_[np.asarray(p.momo.albedo, float), np.asarray(p.color_transform.offset)]


@pytest.mark.parametrize("weighted", [False, True])
def test_conditional_matches_the_explicit_design_matrix(weighted):
    system, mean, prec = _system(0, weighted=weighted)
    m, chol = albedo_offset_conditional(system, SIGMA, OFFSET_SD)
    assert np.allclose(m, mean, atol=1e-4 * (1 + np.abs(mean).max()))
    assert np.allclose(chol @ chol.T, prec, rtol=0, atol=1e-4 * np.abs(prec).max())


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_gibbs_chain_has_the_exact_moments(seed):
    system, mean, prec = _system(seed, weighted=seed == 2)
    cov = np.linalg.inv(prec)
    k = system.jac.shape[2]

    def log_target(p):
        d = _features(p) - mean
        return -0.5 * float(d @ prec @ d)

    prop = AlbedoOffsetConditional(lambda s: system, sigma=SIGMA, offset_sd=OFFSET_SD)
    x, acc = run_chain(prop, log_target, _params(np.zeros(k + 3), k), _features, 3000, seed)
    assert acc > 0.99  # an exact conditional is always accepted
    se = np.sqrt(np.diag(cov) / x.shape[0])
    assert np.max(np.abs(x.mean(0) - mean) / se) < 5.0
    assert np.allclose(x.var(0), np.diag(cov), rtol=0.15)


def test_negative_control_without_its_ratio_the_chain_has_wrong_variances():
    system, mean, prec = _system(0)
    cov = np.linalg.inv(prec)
    k = system.jac.shape[2]

    def log_target(p):
        d = _features(p) - mean
        return -0.5 * float(d @ prec @ d)

    wrong = DropRatio(AlbedoOffsetConditional(lambda s: system, sigma=SIGMA / 3,
                                              offset_sd=OFFSET_SD))
    x, _ = run_chain(wrong, log_target, _params(np.zeros(k + 3), k), _features, 3000, 0)
    assert np.median(x.var(0) / np.diag(cov)) < 0.7  # it samples pi x q, narrower than pi


def test_the_move_declares_albedo_and_colour_and_is_exact_on_a_linear_model():
    system, mean, prec = _system(3)
    k = system.jac.shape[2]
    prop = AlbedoOffsetConditional(lambda s: system, sigma=SIGMA, offset_sd=OFFSET_SD)
    rng = np.random.default_rng(3)
    x = rng.normal(0, 1, k + 3) * 0.1
    for _ in range(5):
        mv = prop(rng, ProposalState(_params(x, k)))
        assert mv.joint and mv.touched == Block.ALBEDO | Block.COLOR_TRANSFORM
        new = _features(mv.params)
        log_alpha = (-0.5 * (new - mean) @ prec @ (new - mean)
                     + 0.5 * (x - mean) @ prec @ (x - mean) + mv.log_q_ratio)
        assert log_alpha == pytest.approx(0.0, abs=0.05)  # float32 normal equations
        x = new


def test_nothing_to_draw_is_the_identity():
    system, _, _ = _system(0)
    k = system.jac.shape[2]
    p = _params(np.zeros(k + 3), k)
    for data in (lambda s: None, lambda s: system._replace(offset_count=0.0),
                 lambda s: system._replace(bright=np.ones_like(system.bright))):
        mv = AlbedoOffsetConditional(data)(np.random.default_rng(0), ProposalState(p))
        assert not mv.touched and mv.params is p
    with pytest.raises(Exception):
        AlbedoOffsetConditional(lambda s: system, offset_sd=0.0)


def _contrast_problem(seed: int, n: int = 60, k: int = 3, count: float = 2.0):
    """A render ``M(kappa) (r0 + J c) + n o`` observed with noise, kappa's prior N(1, 0.3^2)."""
    rng = np.random.default_rng(seed)
    jac = rng.normal(0, 0.3, (n, 3, k))
    mean = rng.uniform(0.1, 0.5, (n, 3))
    mat = ColorTransform(contrast=0.8).matrix()
    photo = ((mean + np.einsum("ncj,j->nc", jac, rng.normal(0, 1, k))) @ mat.T
             + count * np.array([0.02, -0.01, 0.0]) + rng.normal(0, 0.1, (n, 3)))
    sigma = 0.1
    base = albedo_system(jac.astype(np.float32), mean.astype(np.float32),
                         np.full((n, 3), 0.2, np.float32), photo.astype(np.float32),
                         np.zeros(3, np.float32), np.arange(n), 10**6, offset_count=count)

    def system(state):  # the data source renders at the state's contrast (M(1) = I)
        ct = state.params.color_transform
        return _with_contrast(base, np.eye(3), ct.matrix())._replace(key=(ct.contrast,))

    def log_target(p):
        ct = p.color_transform
        c = np.asarray(p.momo.albedo, float)
        o = np.asarray(ct.offset)
        r = photo - (mean + np.einsum("ncj,j->nc", jac, c)) @ ct.matrix().T - count * o
        return (-0.5 * ((ct.contrast - 1.0) / 0.3) ** 2 - 0.5 * c @ c
                - 0.5 * o @ o / OFFSET_SD**2 - 0.5 * float(np.sum(r * r)) / sigma**2)

    def marginal(kappa):  # log p(kappa | data) up to a constant: (c, o) integrated out
        m = ColorTransform(contrast=kappa).matrix()
        a = np.zeros((n, 3, k + 3))
        a[..., :k] = np.einsum("cd,ndj->ncj", m, jac)
        for ch in range(3):
            a[:, ch, k + ch] = count
        a = a.reshape(-1, k + 3)
        y = (photo - mean @ m.T).reshape(-1)
        lam = np.diag(np.r_[np.ones(k), np.full(3, 1 / OFFSET_SD**2)]) + a.T @ a / sigma**2
        h = a.T @ y / sigma**2
        cov = np.linalg.inv(lam)
        m_x = cov @ h
        return (-0.5 * ((kappa - 1.0) / 0.3) ** 2 - 0.5 * y @ y / sigma**2
                + 0.5 * h @ m_x - 0.5 * np.linalg.slogdet(lam)[1]), m_x, cov

    # the contrast's and the albedo and offsets' exact marginal moments
    moments = grid_moments(marginal, np.linspace(0.01, 2.5, 1000))
    return system, sigma, log_target, moments, k


def _contrast_chain(prop, log_target, k, seed, n=4000):
    start = default_square()._replace(
        momo=MoMoCoefficients(np.zeros(0), np.zeros(k), np.zeros(0)),
        color_transform=ColorTransform(contrast=1.0))
    return run_chain(prop, log_target, start, lambda p: np.r_[p.color_transform.contrast,
                                                               _features(p)], n, seed)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_contrast_exchange_samples_the_contrast_marginal(seed):
    system, sigma, log_target, (mu, var, mean_x, var_x), k = _contrast_problem(seed)
    prop = ContrastAlbedoExchange(system, step=2.0 * np.sqrt(var), sigma=sigma,
                                  offset_sd=OFFSET_SD)
    x, acc = _contrast_chain(prop, log_target, k, seed)
    assert acc > 0.3  # a step of 2 marginal sds: accepted as a Metropolis step on kappa alone
    check_exchange_moments(x, mu, var, mean_x, var_x)


def test_contrast_exchange_negative_control_without_its_ratio():
    system, sigma, log_target, (mu, var, mean_x, var_x), k = _contrast_problem(0)
    wrong = DropRatio(ContrastAlbedoExchange(system, step=2.0 * np.sqrt(var),
                                             sigma=sigma, offset_sd=OFFSET_SD))
    x, _ = _contrast_chain(wrong, log_target, k, 0)
    # without the ratio the chain samples pi x q: the albedo and offsets too narrow
    assert np.median(x[500:, 1:].var(0) / var_x) < 0.7
