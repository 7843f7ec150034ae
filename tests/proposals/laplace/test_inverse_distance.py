"""The inverse-distance coordinate ``d0 / d``: round trip, central differences, its domain, exact moves.

Independent truths: the distance read off the stored pose, central
differences of the map ``u -> x`` (Jacobian, its log determinant) and of a
log density with an exact Hessian in ``x`` (gradient and precision in ``u``);
the Crank-Nicolson move's moments over three seeds on a target other than its
approximation.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from face_factory import scene, small_face_model
from laplace_cases import image_scale_case, small_template
from mh_chain import assert_moments, run_chain

from albedo_model.scene_vector import SceneLayout
from proposals.laplace.coordinates import SamplingCoordinates
from proposals.laplace.image_scale import ImageScale
from proposals.laplace.moves import CrankNicolson, GaussianApproximation

SEEDS = (1, 2, 3)


def _coords(params=None, scale=None):
    p = small_template() if params is None else params
    return SamplingCoordinates(SceneLayout.for_params(p), p, scale=scale, inverse_distance=True)


def _distance(p) -> float:
    return float(p.view.translation[2] - p.pose.translation[2])


def _fd_jacobian(c, u, h=1e-6):
    idx = c.scene_indices
    jac = np.empty((c.size, c.size))
    for j in range(c.size):
        e = np.zeros(c.size)
        e[j] = h
        jac[:, j] = (c.x_of_u(u + e)[idx] - c.x_of_u(u - e)[idx]) / (2 * h)
    return jac


def test_round_trip_and_value():
    p = small_template()
    c = _coords(p)
    names = list(c.names)
    assert "inverse_distance" in names and "log_distance" not in names
    k = names.index("inverse_distance")
    u = c.u_of(p)
    assert u[k] == pytest.approx(1.0, abs=1e-12)  # d0 is the template's distance
    q = c.params_of(u + 0.01, p)
    np.testing.assert_allclose(c.u_of(q), u + 0.01, rtol=0, atol=1e-12)
    assert _distance(q) == pytest.approx(_distance(p) / 1.01, rel=1e-12)
    # the other log-scale entries keep their logarithms
    f = names.index("log_focal_length")
    assert u[f] == pytest.approx(math.log(p.camera.focal_length))


def test_jacobian_gradient_and_precision_against_central_differences():
    c = _coords()
    lay = c.layout
    rng = np.random.default_rng(0)
    u = c.u_of(c.template) + rng.normal(0, 0.01, c.size)
    jac = _fd_jacobian(c, u)
    np.testing.assert_allclose(c.jacobian(u), jac, rtol=1e-5, atol=1e-7)
    sign, logdet = np.linalg.slogdet(jac)
    assert sign != 0 and c.log_jacobian(u) == pytest.approx(logdet, abs=1e-6)

    # log p(x): a quadratic in x plus a log-normal prior on the distance d = view_z - t_z;
    # its exact gradient and Hessian in x are handed over, so the precision in u is exact too
    tz = lay.slices()["translation"].start + 2
    vz = float(c.template.view.translation[2])
    # weights in mm^-2 for t_z, so that every term of the precision in u is of order 1
    # (the log |dx/du| curvature 2 / u^2 among them)
    w = np.ones(lay.size)
    w[tz] = 1e-6
    a = rng.normal(0, 0.1, lay.size) * np.sqrt(w)
    x0 = c.x_of_u(u)
    mu, s = math.log(_distance(c.template)) + 0.05, 0.2

    def log_px(x):
        d = vz - x[tz]
        return float(a @ (x - x0) - 0.5 * np.sum(w * (x - x0) ** 2)
                     - (math.log(d) - mu) ** 2 / (2 * s * s) - math.log(d))

    d = vz - x0[tz]
    grad = a.copy()
    # d/dt_z = -d/dd of -(log d - mu)^2 / 2s^2 - log d
    grad[tz] += (math.log(d) - mu) / (s * s * d) + 1.0 / d
    hess = -np.diag(w)
    hess[tz, tz] += -(1.0 - (math.log(d) - mu) - s * s) / (s * s * d * d)
    gu, pu = c.to_coordinates(grad, -hess, u)

    def log_pu(v):
        return log_px(c.x_of_u(v)) + c.log_jacobian(v)

    eps = 1e-5
    k = list(c.names).index("inverse_distance")
    for j in range(c.size):
        up, down = u.copy(), u.copy()
        up[j] += eps
        down[j] -= eps
        assert gu[j] == pytest.approx((log_pu(up) - log_pu(down)) / (2 * eps),
                                      rel=1e-5, abs=1e-6), c.names[j]
    np.testing.assert_allclose(c.gradient(grad, u), gu, rtol=1e-12, atol=1e-12)
    # the precision's row of the inverse distance against second differences
    for j in range(c.size):
        e_j, e_k = np.zeros(c.size), np.zeros(c.size)
        e_j[j], e_k[k] = eps, eps
        fd = -(log_pu(u + e_j + e_k) - log_pu(u + e_j - e_k) - log_pu(u - e_j + e_k)
               + log_pu(u - e_j - e_k)) / (4 * eps * eps)
        assert pu[k, j] == pytest.approx(fd, rel=1e-4, abs=1e-4), c.names[j]
    assert pu[k, k] < 60 and abs(2.0 / u[k] ** 2) > 0.03 * pu[k, k]  # the test sees that term


def test_with_the_image_size_coordinate():
    _, params, _, scale = image_scale_case()
    rng = np.random.default_rng(3)
    c = _coords(params, scale)
    assert {"log_image_size", "inverse_distance"} <= set(c.names)
    u = c.u_of(params) + rng.normal(0, 0.005, c.size)
    jac = _fd_jacobian(c, u)
    np.testing.assert_allclose(c.jacobian(u), jac, rtol=1e-5, atol=1e-7)
    sign, logdet = np.linalg.slogdet(jac)
    assert sign != 0 and c.log_jacobian(u) == pytest.approx(logdet, abs=1e-6)
    g = rng.normal(size=c.layout.size)  # a linear log density in x: its gradient in u
    eps = 1e-6
    for j in range(c.size):
        up, down = u.copy(), u.copy()
        up[j] += eps
        down[j] -= eps
        fd = ((g @ c.x_of_u(up) + c.log_jacobian(up))
              - (g @ c.x_of_u(down) + c.log_jacobian(down))) / (2 * eps)
        assert c.gradient(g, u)[j] == pytest.approx(fd, rel=1e-5, abs=1e-5), c.names[j]


def test_outside_the_domain_has_density_zero():
    c = _coords()
    u = c.u_of(c.template)
    k = list(c.names).index("inverse_distance")
    for bad in (0.0, -0.3):
        v = u.copy()
        v[k] = bad
        assert c.log_jacobian(v) == -math.inf
        c.x_of_u(v)  # no error: the move's ratio (-inf) refuses it


@pytest.mark.parametrize("seed", SEEDS)
def test_crank_nicolson_keeps_a_target_off_the_approximation(seed):
    c = _coords()
    rng = np.random.default_rng(seed)
    u0 = c.u_of(c.template)
    sd = np.exp(rng.normal(-2.5, 0.5, c.size))
    mean = u0 + 0.5 * sd * rng.normal(size=c.size)
    prec = np.diag(1.0 / sd ** 2)

    def log_p(params):
        v = c.u_of(params)
        e = v - mean
        return -0.5 * float(e @ prec @ e) - c.log_jacobian(v)

    approx = GaussianApproximation(mean + 0.2 * sd, np.diag(1.0 / (1.1 * sd) ** 2))
    samples, acc = run_chain(CrankNicolson(c, approx, 0.5), log_p, c.template, c.u_of, 12_000,
                             seed=seed)
    assert 0.1 < acc < 0.99
    assert_moments(samples, mean, sd, burn=1000)


@pytest.mark.parametrize("inverse", [False, True])
def test_every_coordinate_is_in_one_block(inverse):
    """The block moves cover every coordinate: the image size and the distance in the geometry's."""
    from proposals.laplace.schedule import GAUSSIAN_BLOCKS

    model = small_face_model(subdivisions=3)
    params = scene(64, 64, yaw=0.2, translation=(0.0, 0.0, -950.0))
    n = model.shape.dim // 3
    c = SamplingCoordinates(SceneLayout.for_params(params), params,
                            scale=ImageScale.of_model(model, params, np.arange(0, n, 3)),
                            inverse_distance=inverse)
    groups = [GAUSSIAN_BLOCKS[f] for f in ("gaussian-geometry", "gaussian-albedo",
                                             "gaussian-shading")]
    for name in c.names:
        hits = [g for g in groups if name.startswith(g)]
        assert len(hits) == 1, name
    geometry = [n for n in c.names if n.startswith(groups[0])]
    assert "log_image_size" in geometry
    assert ("inverse_distance" if inverse else "log_distance") in geometry
