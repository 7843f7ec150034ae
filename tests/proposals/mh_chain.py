"""Test helpers for the proposal tests: a plain MH chain, random states, block diffs."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from emcee import autocorr

from albedo_model.params import (
    Block,
    ColorTransform,
    MoMoCoefficients,
    RenderParameter,
    SHLight,
    default_square,
    fit_to_image_size,
)
from proposals.base import Move
from proposals.base import ProposalState


def run_chain(proposal, log_target: Callable[[RenderParameter], float], start: RenderParameter,
              features: Callable[[RenderParameter], np.ndarray], n_steps: int,
              seed: int) -> tuple[np.ndarray, float]:
    """Metropolis-Hastings with ``proposal`` against ``log_target``.

    Returns
    -------
    samples : (n_steps, d) float64, ``features`` of the state after each step
    acceptance : float, fraction of accepted moves
    """
    rng = np.random.default_rng(seed)
    x, lp = start, log_target(start)
    out = np.empty((n_steps, np.atleast_1d(features(start)).shape[0]))
    accepted = 0
    for i in range(n_steps):
        move = proposal(rng, ProposalState(x))
        lp_new = log_target(move.params)
        log_alpha = lp_new - lp + move.log_q_ratio
        if np.log(rng.random()) < log_alpha:
            x, lp = move.params, lp_new
            accepted += 1
        out[i] = features(x)
    return out, accepted / n_steps


class DropRatio:
    """Negative control: the wrapped proposal with its log ratio replaced by 0."""

    def __init__(self, inner):
        self.inner, self.name, self.touches = inner, inner.name, inner.touches

    def __call__(self, rng, state) -> Move:
        return self.inner(rng, state)._replace(log_q_ratio=0.0)


def base_state(width: int = 250, height: int = 250) -> RenderParameter:
    return fit_to_image_size(default_square(), width, height)


def random_state(rng: np.random.Generator, *, n_shape: int = 50, n_albedo: int = 50,
                 n_expression: int = 5) -> RenderParameter:
    """A random but valid state: face ~1 m in front, small angles, random light and colour."""
    p = base_state()
    pose = p.pose._replace(
        yaw=float(rng.normal(0, 0.3)), pitch=float(rng.normal(0, 0.2)),
        roll=float(rng.normal(0, 0.1)),
        translation=(float(rng.normal(0, 20)), float(rng.normal(0, 20)),
                     float(-1000 + rng.normal(0, 100))),
    )
    cam = p.camera._replace(focal_length=float(7.5 * np.exp(rng.normal(0, 0.1))),
                            principal_point=tuple(float(v) for v in rng.normal(0, 0.05, 2)))
    light = SHLight(SHLight.frontal().coefficients + rng.normal(0, 0.05, (9, 3)))
    ct = ColorTransform(gain=tuple(float(v) for v in np.exp(rng.normal(0, 0.1, 3))),
                        contrast=float(1 + rng.normal(0, 0.05)),
                        offset=tuple(float(v) for v in rng.normal(0, 0.01, 3)))
    momo = MoMoCoefficients(rng.normal(size=n_shape), rng.normal(size=n_albedo),
                            rng.normal(size=n_expression), "model.h5")
    return p._replace(pose=pose, camera=cam, environment_map=light, color_transform=ct,
                      momo=momo, specular_exponent=float(20 * np.exp(rng.normal(0, 0.2))))


def changed_blocks(a: RenderParameter, b: RenderParameter) -> Block:
    """Blocks whose fields differ between two states (view, image size, URI must not)."""
    assert a.view == b.view and a.image_size == b.image_size
    assert a.momo.model_uri == b.momo.model_uri
    out = Block.NONE
    if a.pose != b.pose:
        out |= Block.POSE
    if a.camera != b.camera:
        out |= Block.CAMERA
    for blk, fld in ((Block.SHAPE, "shape"), (Block.EXPRESSION, "expression"),
                     (Block.ALBEDO, "albedo")):
        if not np.array_equal(getattr(a.momo, fld), getattr(b.momo, fld)):
            out |= blk
    if not np.array_equal(a.environment_map.coefficients, b.environment_map.coefficients):
        out |= Block.LIGHT
    if a.directional_light.direction != b.directional_light.direction:
        out |= Block.DIRECTIONAL_ANGLES
    if a.directional_light._replace(direction=b.directional_light.direction) != b.directional_light:
        out |= Block.DIRECTIONAL_STRENGTH
    if a.color_transform != b.color_transform:
        out |= Block.COLOR_TRANSFORM
    if a.specular_exponent != b.specular_exponent:
        out |= Block.SPECULAR_EXPONENT
    return out


def _ess(x: np.ndarray) -> float:
    tau = float(autocorr.integrated_time(x, c=5, tol=0, quiet=True)[0])
    return x.shape[0] / max(tau, 1.0)


def assert_moments(samples: np.ndarray, mean, std, *, z: float = 5.0, burn: int = 1000,
                   min_ess: float = 200.0) -> None:
    """Sample means and sds agree with the target's within ``z`` Monte-Carlo standard errors.

    The standard errors use the integrated autocorrelation time (emcee's
    estimator) of each coordinate, and of its squared deviation for the sd
    (``se(sd) = sd sqrt(var(e^2)) / (2 sd^2 sqrt(ESS))``, ``e = x - mean``).
    A chain with fewer than ``min_ess`` effective samples fails outright.
    """
    s = np.asarray(samples, np.float64)[burn:]
    s = s.reshape(s.shape[0], -1)
    mean = np.broadcast_to(np.asarray(mean, np.float64).reshape(-1), s.shape[1:])
    std = np.broadcast_to(np.asarray(std, np.float64).reshape(-1), s.shape[1:])
    for j in range(s.shape[1]):
        x = s[:, j]
        ess = _ess(x)
        assert ess > min_ess, f"coordinate {j}: only {ess:.0f} effective samples"
        se_mean = std[j] / np.sqrt(ess)
        assert abs(x.mean() - mean[j]) < z * se_mean, (
            f"coordinate {j}: mean {x.mean():.5g} vs {mean[j]:.5g} (se {se_mean:.3g})")
        e2 = (x - mean[j]) ** 2
        se_sd = np.std(e2) / (2.0 * std[j] * np.sqrt(_ess(e2)))
        sd = np.sqrt(e2.mean())
        assert abs(sd - std[j]) < z * se_sd, (
            f"coordinate {j}: sd {sd:.5g} vs {std[j]:.5g} (se {se_sd:.3g})")


def moment_errors(samples: np.ndarray, mean, std, *, burn: int = 1000) -> np.ndarray:
    """Largest error, in target sds, of the sample mean and of the sample sd (per coordinate).

    For negative controls: a chain with a wrong ratio must be off by a clear margin.
    """
    s = np.asarray(samples, np.float64)[burn:]
    s = s.reshape(s.shape[0], -1)
    mean = np.broadcast_to(np.asarray(mean, np.float64).reshape(-1), s.shape[1:])
    std = np.broadcast_to(np.asarray(std, np.float64).reshape(-1), s.shape[1:])
    return np.maximum(np.abs(s.mean(0) - mean) / std, np.abs(s.std(0) / std - 1.0))


def check_exchange_moments(x: np.ndarray, mean_k: float, var_k: float, mean_x: np.ndarray,
                           var_x: np.ndarray, burn: int = 500) -> None:
    """Assert a contrast-exchange chain's draws ``[kappa, x...]`` have the exact moments.

    ~3,500 draws at a few steps per independent draw: 0.1 sd on the means, 15 %
    on the variances.
    """
    x = x[burn:]
    assert abs(x[:, 0].mean() - mean_k) < 0.1 * np.sqrt(var_k)
    assert abs(x[:, 0].var() / var_k - 1.0) < 0.15
    assert np.max(np.abs(x[:, 1:].mean(0) - mean_x) / np.sqrt(var_x)) < 0.15
    assert np.allclose(x[:, 1:].var(0), var_x, rtol=0.15)


def grid_moments(marginal, grid: np.ndarray) -> tuple[float, float, np.ndarray, np.ndarray]:
    """Exact moments of ``kappa`` and of ``x`` from ``marginal(kappa) -> (log p, E[x|k], Cov[x|k])``.

    ``kappa`` is integrated on the fine ``grid``; returns ``(mean_k, var_k, mean_x, var_x)``.
    """
    out = [marginal(k) for k in grid]
    lp = np.array([o[0] for o in out])
    w = np.exp(lp - lp.max())
    w /= w.sum()
    mean_k = float(w @ grid)
    m_x = np.array([o[1] for o in out])
    mean_x = w @ m_x
    var_x = w @ (np.array([np.diag(o[2]) for o in out]) + m_x**2) - mean_x**2
    return mean_k, float(w @ (grid - mean_k) ** 2), mean_x, var_x
