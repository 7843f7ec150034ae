"""The Laplace approximation widened by the posterior's curvature: exact on Gaussians, nowhere narrowed."""

import numpy as np
import pytest

from albedo_model.errors import InputError
from mcmcfit.fitting.curvature_widening import curvature_widened, whitened_precision
from proposals.laplace.moves import GaussianApproximation
from proposals.laplace.widening import CURVATURE_MAX_RATIO, widened_by_curvature

D = 12


def _spd(rng: np.random.Generator, d: int = D) -> np.ndarray:
    a = rng.normal(size=(d, d))
    return a @ a.T / d + np.eye(d)


def _gaussian_gradient(mean: np.ndarray, precision: np.ndarray):
    """``u -> (log N(u; mean, precision^-1), gradient)`` up to a constant."""
    def grad(u):
        r = u - mean
        return -0.5 * float(r @ precision @ r), -(precision @ r)
    return grad


def _whitened_variances(approx: GaussianApproximation, reference: GaussianApproximation,
                        directions: np.ndarray) -> np.ndarray:
    """Variances of ``approx`` along ``reference``'s whitened unit ``directions`` (columns)."""
    z_cov = np.linalg.solve(reference.chol_cov, approx.covariance())
    z_cov = np.linalg.solve(reference.chol_cov, z_cov.T).T
    return np.einsum("ik,ij,jk->k", directions, z_cov, directions)


@pytest.mark.parametrize("seed", range(3))
def test_the_whitened_precision_of_a_gaussian_is_exact(seed):
    """Central differences of a quadratic's gradient are exact: L^T P_true L, whatever the step."""
    rng = np.random.default_rng(seed)
    approx = GaussianApproximation(rng.normal(size=D), _spd(rng))
    p_true = _spd(rng)
    grad = _gaussian_gradient(rng.normal(size=D), p_true)
    lc = approx.chol_cov
    for scale in (0.3, 1.0, 2.0):
        h = whitened_precision(grad, approx, approx.mean, scale=scale)
        np.testing.assert_allclose(h, lc.T @ p_true @ lc, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("seed", range(3))
def test_a_flatter_posterior_is_matched_and_a_sharper_one_is_not_narrowed(seed):
    """The approximation's precision with two directions 8x / 0.5x the variance, one 4x sharper."""
    rng = np.random.default_rng(seed)
    approx = GaussianApproximation(rng.normal(size=D), _spd(rng))
    q, _ = np.linalg.qr(rng.normal(size=(D, D)))  # whitened orthonormal directions
    ratios = np.ones(D)
    ratios[:3] = [8.0, 2.0, 0.25]  # true variance / approximation's, along q[:, k]
    # The true posterior's whitened covariance Q diag(r) Q^T, back in u
    cov_true = approx.chol_cov @ (q * ratios) @ q.T @ approx.chol_cov.T
    grad = _gaussian_gradient(approx.mean, np.linalg.inv(cov_true))
    widened, record = curvature_widened(grad, approx, approx.mean)
    got = _whitened_variances(widened, approx, q)
    np.testing.assert_allclose(got[:2], [8.0, 2.0], rtol=1e-6)
    np.testing.assert_allclose(got[2:], 1.0, rtol=1e-6)  # the sharper one is left as it was
    assert record["widened"] == 2
    assert record["ratios"] == pytest.approx([8.0, 2.0], rel=1e-6)
    assert record["eigenvalues"][0] == pytest.approx(0.125, rel=1e-6)
    np.testing.assert_array_equal(widened.mean, approx.mean)


def test_flat_and_negative_curvature_are_capped():
    approx = GaussianApproximation(np.zeros(4), np.diag([4.0, 1.0, 2.0, 0.5]))
    found = widened_by_curvature(approx, np.diag([-0.7, 0.0, 0.5, 3.0]))
    assert sorted(found.ratios) == pytest.approx([2.0, CURVATURE_MAX_RATIO, CURVATURE_MAX_RATIO])
    got = _whitened_variances(found.approx, approx, np.eye(4))
    np.testing.assert_allclose(got, [CURVATURE_MAX_RATIO, CURVATURE_MAX_RATIO, 2.0, 1.0],
                               rtol=1e-9)


def test_nothing_flatter_leaves_the_approximation():
    approx = GaussianApproximation(np.zeros(3), np.diag([4.0, 1.0, 2.0]))
    found = widened_by_curvature(approx, np.diag([1.0, 1.5, 3.0]))
    assert found.approx is approx and found.ratios.size == 0


def test_a_step_out_of_the_domain_keeps_that_column_of_the_approximation():
    """A non-finite gradient (a step out of the parameters' domain) is no evidence of flatness."""
    approx = GaussianApproximation(np.zeros(3), np.eye(3))

    def grad(u):
        if u[0] > 0.5:
            return float("nan"), np.full(3, np.nan)
        return 0.0, -np.array([0.1, 0.1, 0.1]) * u

    h = whitened_precision(grad, approx, np.zeros(3))
    np.testing.assert_allclose(h, np.diag([1.0, 0.1, 0.1]))


def test_bad_inputs_are_refused():
    approx = GaussianApproximation(np.zeros(3), np.eye(3))
    grad = _gaussian_gradient(np.zeros(3), np.eye(3))
    with pytest.raises(InputError, match="centre"):
        whitened_precision(grad, approx, np.zeros(2))
    with pytest.raises(InputError, match="scale"):
        whitened_precision(grad, approx, np.zeros(3), scale=0.0)
    with pytest.raises(InputError, match="whitened precision"):
        widened_by_curvature(approx, np.eye(2))
    with pytest.raises(InputError, match="whitened precision"):
        widened_by_curvature(approx, np.full((3, 3), np.nan))
    with pytest.raises(InputError, match="max_ratio"):
        widened_by_curvature(approx, np.eye(3), max_ratio=1.0)


@pytest.mark.embree
def test_a_fit_with_the_hessian_metric_records_what_it_widened():
    """``metric="hessian"`` end to end: each chain's widening is recorded, the default has none.

    On a small synthetic face the exact gradient's central differences see the
    image posterior flatter than Gauss-Newton in some directions (widened,
    ratios capped at :data:`CURVATURE_MAX_RATIO`) and never narrower.
    """
    from face_factory import scene, small_face_model, synthetic_target

    from mcmcfit.fitting.config import FitConfig
    from mcmcfit.fitting.fit import fit

    model = small_face_model()
    image, clicks = synthetic_target(model, scene(64, 64, yaw=0.25, pitch=-0.1))
    cfg = FitConfig(steps=60, warmup_steps=20, landmark_steps=100, sigma_lm=2.0, chains=1,
                    parallel=False, mode_rounds=1, mode_steps=3, metric="hessian")
    res = fit(image, clicks, model, config=cfg, seed=3)
    (record,) = res.stopping["mode"]["metric"]
    assert record["widened"] >= 1 and record["scale"] > 0
    ratios = np.asarray(record["ratios"])
    assert np.all(ratios >= 1.0) and np.all(ratios <= CURVATURE_MAX_RATIO)
    plain = fit(image, clicks, model, config=cfg.replace(metric="gauss-newton"), seed=3)
    assert plain.stopping["mode"]["metric"] == [None]
