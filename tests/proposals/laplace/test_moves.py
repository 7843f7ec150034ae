"""Sampling coordinates and the Gaussian moves: round trips, Jacobians, exact moments, controls.

The toy target is a correlated Gaussian *in the sampling coordinates* (its
density in the stored parameters carries ``-log |dx/du|``), different from
the approximation the moves are built on (shifted mean, scaled and rotated
covariance), so that only an exact Metropolis-Hastings ratio recovers its
moments. Statistics are asserted over three seeds with a stated tolerance.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from laplace_cases import small_template
from mh_chain import DropRatio, assert_moments, moment_errors, run_chain

from albedo_model.errors import InputError
from albedo_model.params import Block
from albedo_model.scene_vector import SceneLayout
from proposals.base import Move, ProposalState
from proposals.gradient import leapfrog
from proposals.laplace.coordinates import HELD, SamplingCoordinates
from proposals.laplace.moves import (
    CrankNicolson,
    GaussianApproximation,
    GaussianBlockConditional,
    GaussianHMC,
)
from proposals.laplace.random_walk import GaussianRandomWalk

SEEDS = (1, 2, 3)


def _coords():
    p = small_template()
    return SamplingCoordinates(SceneLayout.for_params(p), p)


class Target:
    """``N(mean, cov)`` in the coordinates u; ``log_p`` is the density of the stored parameters."""

    def __init__(self, coords: SamplingCoordinates, seed: int):
        rng = np.random.default_rng(seed)
        u0 = coords.u_of(coords.template)
        d = coords.size
        # scales like a fit's: log entries 0.05, coefficients 0.3, the rest 0.01-1
        self.sd = np.exp(rng.normal(-2.0, 0.7, d))
        self.mean = u0 + 0.5 * self.sd * rng.normal(size=d)
        q, _ = np.linalg.qr(rng.normal(size=(d, d)))
        corr = q @ np.diag(np.exp(rng.normal(0.0, 0.5, d))) @ q.T
        corr /= np.sqrt(np.outer(np.diag(corr), np.diag(corr)))
        self.cov = corr * np.outer(self.sd, self.sd)
        self.prec = np.linalg.inv(self.cov)
        self.coords = coords
        self.calls = 0

    def log_u(self, u):
        e = u - self.mean
        return -0.5 * float(e @ self.prec @ e)

    def log_p(self, params) -> float:
        u = self.coords.u_of(params)
        return self.log_u(u) - self.coords.log_jacobian(u)

    def grad(self, params):
        self.calls += 1
        u = self.coords.u_of(params)
        return self.log_u(u), -self.prec @ (u - self.mean)

    def approximation(self, seed: int) -> GaussianApproximation:
        """A deliberately imperfect approximation: mean off by 0.2 sd, sds scaled by 0.9-1.1."""
        rng = np.random.default_rng(seed + 100)
        shift = 0.2 * self.sd * rng.normal(size=self.sd.size)
        scale = np.exp(rng.uniform(-0.1, 0.1, self.sd.size))
        cov = self.cov * np.outer(scale, scale)
        return GaussianApproximation(self.mean + shift, np.linalg.inv(cov))


def test_coordinates_round_trip_hold_and_log_scale():
    c = _coords()
    p = small_template()._replace(camera=small_template().camera._replace(principal_point=(0.1, -0.2)))
    c = SamplingCoordinates(SceneLayout.for_params(p), p)
    u = c.u_of(p)
    assert c.size == SceneLayout.for_params(p).size - 5  # gain (3) and principal point (2)
    assert set(HELD) == {"gain", "principal_point"}
    names = list(c.names)
    assert names[names.index("log_distance")] == "log_distance"
    assert u[names.index("log_focal_length")] == pytest.approx(math.log(p.camera.focal_length))
    d = float(p.view.translation[2] - p.pose.translation[2])
    assert u[names.index("log_distance")] == pytest.approx(math.log(d))
    q = c.params_of(u + 0.01, p)
    assert q.camera.principal_point == (0.1, -0.2) and q.color_transform.gain == p.color_transform.gain
    np.testing.assert_allclose(c.u_of(q), u + 0.01, rtol=0, atol=1e-12)
    assert c.touches == Block.ALL & ~Block.DIRECTIONAL  # no directional light in the scene
    with pytest.raises(InputError):
        c.u_of(p._replace(camera=p.camera._replace(focal_length=-1.0)))


def test_log_jacobian_is_the_log_determinant():
    c = _coords()
    u = c.u_of(c.template) + np.random.default_rng(0).normal(0, 0.01, c.size)
    h = 1e-6
    jac = np.empty((c.size, c.size))
    idx = c.scene_indices
    for j in range(c.size):
        e = np.zeros(c.size)
        e[j] = h
        jac[:, j] = (c.x_of_u(u + e)[idx] - c.x_of_u(u - e)[idx]) / (2 * h)
    sign, logdet = np.linalg.slogdet(jac)
    assert sign != 0 and c.log_jacobian(u) == pytest.approx(logdet, abs=1e-6)


def test_to_coordinates_turns_a_lognormal_into_a_gaussian():
    c = _coords()
    lay = c.layout
    u = c.u_of(c.template)
    f = lay.slices()["focal_length"].start
    k = list(c.scene_indices).index(f)
    s, med = 0.4, 6.0

    def log_px(x):  # a log-normal density in the focal length, nothing else
        return -((math.log(x) - math.log(med)) ** 2) / (2 * s * s) - math.log(x)

    x = c.x_of_u(u)[f]
    g = -(math.log(x) - math.log(med)) / (s * s * x) - 1.0 / x
    h = (1.0 - (math.log(x) - math.log(med)) - s * s) / (s * s * x * x)  # -d2/dx2
    gx, hx = np.zeros(lay.size), np.zeros((lay.size, lay.size))
    gx[f], hx[f, f] = g, h
    gu, pu = c.to_coordinates(gx, hx, u)
    # in u: log N(u; log med, s^2) (the log-normal's 1/x cancels the Jacobian e^u)
    assert pu[k, k] == pytest.approx(1.0 / (s * s), rel=1e-9)
    assert gu[k] == pytest.approx(-(u[k] - math.log(med)) / (s * s), rel=1e-9)
    eps = 1e-4  # and the gradient is that of log p(x(u)) + log|dx/du| by finite differences
    up, down = u.copy(), u.copy()
    up[k] += eps
    down[k] -= eps
    fd = ((log_px(c.x_of_u(up)[f]) + c.log_jacobian(up))
          - (log_px(c.x_of_u(down)[f]) + c.log_jacobian(down))) / (2 * eps)
    assert gu[k] == pytest.approx(fd, rel=1e-6)


def test_gaussian_approximation_factorises_and_rejects_bad_input():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(4, 4))
    prec = a @ a.T + 4 * np.eye(4)
    g = GaussianApproximation(np.zeros(4), prec)
    np.testing.assert_allclose(g.covariance(), np.linalg.inv(prec), rtol=1e-10)
    draws = np.array([g.draw(rng) for _ in range(20_000)])
    np.testing.assert_allclose(np.cov(draws.T), np.linalg.inv(prec), atol=0.02)
    with pytest.raises(InputError):
        GaussianApproximation(np.zeros(4), -prec)
    with pytest.raises(InputError):
        GaussianApproximation(np.zeros(3), prec)


def _check(samples, target, burn=1000):
    """Means and sds within 5 Monte-Carlo standard errors (from each coordinate's ESS)."""
    assert_moments(samples, target.mean, target.sd, burn=burn)


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("rho", [0.0, 0.7])
def test_crank_nicolson_keeps_the_target(seed, rho):
    c = _coords()
    target = Target(c, seed)
    move = CrankNicolson(c, target.approximation(seed), rho)
    samples, acc = run_chain(move, target.log_p, c.template, c.u_of, 20_000, seed=seed)
    assert 0.05 < acc < 0.95 and move.touches == c.touches
    _check(samples, target)


@pytest.mark.parametrize("seed", SEEDS)
def test_block_conditionals_keep_the_target(seed):
    c = _coords()
    target = Target(c, seed)
    approx = target.approximation(seed)
    names = np.array(c.names)
    blocks = [np.array([n.startswith(p) for n in names]) for p in
              (("shape", "expression", "angles", "translation", "log_"), ("light", "contrast",
                                                                         "offset", "albedo"))]
    moves = [GaussianBlockConditional(c, approx, m, name=f"b{i}", rho=r)
             for i, m in enumerate(blocks) for r in (0.0, 0.5)]
    # a block drawn about a widened approximation (the "geometry-wide" family) is exact too
    moves.append(GaussianBlockConditional(c, approx.widened(blocks[0], 2.0), blocks[0],
                                          name="wide", rho=0.5))

    class Cycle:
        name, touches = "cycle", Block.ALL

        def __call__(self, rng, state):
            return moves[int(rng.integers(len(moves)))](rng, state)

    samples, acc = run_chain(Cycle(), target.log_p, c.template, c.u_of, 24_000, seed=seed)
    assert 0.1 < acc < 1.0
    _check(samples, target)
    assert moves[0].touches == Block.SHAPE | Block.EXPRESSION | Block.POSE | Block.CAMERA \
        | Block.SPECULAR_EXPONENT  # log_specular_exponent is a log_ entry
    with pytest.raises(InputError):
        GaussianBlockConditional(c, approx, np.zeros(c.size, bool))


@pytest.mark.parametrize("random_steps", [False, True])
@pytest.mark.parametrize("seed", SEEDS)
def test_hmc_keeps_the_target(seed, random_steps):
    c = _coords()
    target = Target(c, seed)
    move = GaussianHMC(c, target.approximation(seed), target.grad, step=0.6, n_leapfrog=3,
                       random_steps=random_steps)
    samples, acc = run_chain(move, target.log_p, c.template, c.u_of, 5000, seed=seed)
    assert 0.4 < acc < 1.0
    _check(samples, target, burn=300)
    if random_steps:  # 1-5 steps, mean 3: the sum over 5,000 moves has sd ~100
        assert 2.8 * 5000 < target.calls < 3.2 * 5000
    else:
        assert target.calls <= 3 * 5000 + 1  # one gradient per leapfrog step, the ends cached


@pytest.mark.parametrize("seed", SEEDS)
def test_hmc_with_a_surrogate_gradient_keeps_the_target(seed):
    """Kicks from another function of the position (here the gradient of a Gaussian 1.1x
    wider than the target and off-centre, as the mode's-triangles gradient of
    ``hmc_triangles="mode"`` is another function): the trajectory is still a volume-preserving involution and the exact
    ratio keeps the target."""
    c = _coords()
    target = Target(c, seed)
    other = target.approximation(seed + 7)
    prec, mean = other.precision / 1.21, other.mean

    def surrogate(params):
        u = c.u_of(params)
        return target.log_u(u), -prec @ (u - mean)

    move = GaussianHMC(c, target.approximation(seed), surrogate, step=0.5, n_leapfrog=3)
    samples, acc = run_chain(move, target.log_p, c.template, c.u_of, 6000, seed=seed)
    assert 0.2 < acc < 1.0
    _check(samples, target, burn=300)


@pytest.mark.parametrize("failure", ["raises", "invalid", "inf"])
def test_hmc_trajectory_leaving_the_domain_is_refused(failure):
    c = _coords()
    target = Target(c, 1)
    start = c.template

    def grad(params):
        if params is start:
            return target.grad(params)
        if failure == "raises":
            raise ValueError("math domain error")  # e.g. a log of a negative distance
        if failure == "invalid":
            raise InputError("vertices contain NaN or inf")  # the renderer's input check
        return -np.inf, np.full(c.size, np.nan)

    move = GaussianHMC(c, target.approximation(1), grad, step=0.6, n_leapfrog=3)
    for seed in SEEDS:
        out = move(np.random.default_rng(seed), ProposalState(start))
        assert out.log_q_ratio == -np.inf


class FrozenHMC:
    """Negative control: every kick of a trajectory uses the gradient at its start."""

    def __init__(self, hmc: GaussianHMC):
        self.hmc, self.name, self.touches = hmc, hmc.name, hmc.touches

    def __call__(self, rng, state) -> Move:
        h, c, a = self.hmc, self.hmc.coords, self.hmc.approx
        u = c.u_of(state.params)
        z = np.linalg.solve(a.chol_cov, u - a.mean)
        g = a.chol_cov.T @ h.grad(state.params)[1]
        p = rng.normal(size=z.size)
        z_new, p_new, _ = leapfrog(z, p, g, lambda y: g, h.step, np.ones(z.size), h.n_leapfrog)
        u_new = a.mean + a.chol_cov @ z_new
        ratio = 0.5 * float(p @ p - p_new @ p_new) + c.log_jacobian(u_new) - c.log_jacobian(u)
        return Move(c.params_of(u_new, state.params), ratio, self.touches, h.name, joint=True)


def test_widened_approximation_scales_the_block():
    c = _coords()
    target = Target(c, 2)
    approx = target.approximation(2)
    mask = np.arange(c.size) < 4
    wide = approx.widened(mask, 2.0)
    cov, cov2 = approx.covariance(), wide.covariance()
    f = np.where(mask, 2.0, 1.0)
    np.testing.assert_allclose(cov2, cov * np.outer(f, f), rtol=1e-9, atol=1e-12)
    with pytest.raises(InputError):
        approx.widened(mask, 0.0)


@pytest.mark.parametrize("seed", SEEDS)
def test_random_walk_keeps_the_target(seed):
    c = _coords()
    target = Target(c, seed)
    approx = target.approximation(seed)
    move = GaussianRandomWalk(c, approx, np.ones(c.size, bool), 2.4 / math.sqrt(c.size))
    samples, acc = run_chain(move, target.log_p, c.template, c.u_of, 30_000, seed=seed)
    assert 0.1 < acc < 0.6 and move.touches == c.touches
    _check(samples, target)
    assert move.with_scale(0.5).scale == 0.5 and move.with_scale(0.5).name == move.name
    with pytest.raises(InputError):
        GaussianRandomWalk(c, approx, np.zeros(c.size, bool))
    with pytest.raises(InputError):
        GaussianRandomWalk(c, approx, np.ones(c.size, bool), 0.0)


def test_random_walk_escapes_the_approximations_tails():
    """A state far in the approximation's tails, typical for a wider posterior: the walk moves on.

    Target ``N(m, 9 S)`` (three times wider than the approximation), started 6
    approximation sds out along a coordinate: independent Crank-Nicolson draws
    are refused (their acceptance is ``w(u') / w(u)`` with ``w`` the target over
    the approximation, largest out there), the walk's are not.
    """
    c = _coords()
    target = Target(c, 1)
    approx = GaussianApproximation(target.mean, target.prec)
    wide = Target(c, 1)
    wide.prec = target.prec / 9.0
    start = target.mean + 6.0 * target.sd * np.eye(c.size)[0]
    params = c.params_of(start)
    walk = GaussianRandomWalk(c, approx, np.ones(c.size, bool), 2.4 / math.sqrt(c.size))
    pcn = CrankNicolson(c, approx, 0.0)
    _, acc_walk = run_chain(walk, wide.log_p, params, c.u_of, 300, seed=1)
    _, acc_pcn = run_chain(pcn, wide.log_p, params, c.u_of, 300, seed=1)
    assert acc_walk > 0.2 and acc_pcn < 0.02, (acc_walk, acc_pcn)


class CrankNicolsonAsWalk:
    """Negative control: a Crank-Nicolson draw given a symmetric walk's ratio (the approximation's densities left out)."""

    def __init__(self, pcn: CrankNicolson):
        self.pcn, self.name, self.touches = pcn, pcn.name, pcn.touches

    def __call__(self, rng, state) -> Move:
        move = self.pcn(rng, state)
        c = self.pcn.coords
        u, u_new = c.u_of(state.params), c.u_of(move.params)
        return move._replace(log_q_ratio=c.log_jacobian(u_new) - c.log_jacobian(u))


@pytest.mark.parametrize("control", ["drop", "frozen", "walk"])
def test_wrong_ratios_give_wrong_moments(control):
    """Controls for the tests above: without the exact ratio the moments are off.

    Same targets and seeds, where the exact moves pass the 5-standard-error
    test (their worst errors 0.04-0.23 target sds); the controls' worst
    errors must exceed 0.3.
    """
    worst = []
    for seed in SEEDS:
        c = _coords()
        target = Target(c, seed)
        approx = target.approximation(seed)
        if control == "drop":
            move = DropRatio(CrankNicolson(c, approx, 0.0))
            steps = 6000
        elif control == "walk":
            move = CrankNicolsonAsWalk(CrankNicolson(c, approx, 0.7))
            steps = 6000
        else:
            move = FrozenHMC(GaussianHMC(c, approx, target.grad, step=0.6, n_leapfrog=3))
            steps = 3000
        samples, _ = run_chain(move, target.log_p, c.template, c.u_of, steps, seed=seed)
        worst.append(moment_errors(samples, target.mean, target.sd, burn=300).max())
    assert min(worst) > 0.3, worst
