"""The image-size coordinate: against the camera's own projection and central differences.

Small synthetic face model (``face_factory``). The log radius is checked
against :func:`albedo_model.camera.project` of the model's own instance (an
independent path: the model's ``shape_instance`` and the renderer's camera), its
gradient and the coordinates' Jacobian, log determinant and gradient against
central differences, and the coordinate against what it is for: the image size
does not move when the focal length and the distance change together.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from face_factory import small_face_model
from laplace_cases import image_scale_case

from albedo_model.camera import pixel_scale, project
from albedo_model.errors import InputError
from albedo_model.params import MoMoCoefficients
from albedo_model.scene_vector import SceneLayout
from proposals.laplace.coordinates import SamplingCoordinates
from proposals.laplace.image_scale import ImageScale, anchor_vertices


@pytest.fixture(scope="module")
def setting():
    return image_scale_case()


def test_anchor_vertices_of_seen_triangles():
    tri = np.array([[0, 1, 2], [2, 3, 4], [5, 6, 7]])
    np.testing.assert_array_equal(anchor_vertices(tri, np.array([-1, 1, 0, 1])), [0, 1, 2, 3, 4])
    assert anchor_vertices(tri, np.array([0, 1, 2]), max_anchors=4).tolist() == [0, 2, 5, 7]
    with pytest.raises(InputError):
        anchor_vertices(tri, np.array([-1, -1]))


def test_log_radius_is_that_of_the_projected_instance(setting):
    model, params, ids, scale = setting
    verts = model.shape_instance(params.momo.shape, params.momo.expression)[ids]
    px, _ = project(verts, params.pose, params.view, params.camera, params.image_size)
    q = px - px.mean(axis=0)
    radius = math.sqrt(np.mean(np.sum(q * q, axis=1)))
    fx, fy = pixel_scale(params.camera, params.image_size)
    assert fx == fy  # square pixels here: the unit-focal radius is the radius over f
    lay = SceneLayout.for_params(params)
    assert scale.log_radius(lay.vector(params)) == pytest.approx(
        math.log(radius / params.camera.focal_length), abs=1e-12)


def test_gradient_matches_central_differences(setting):
    _, params, _, scale = setting
    lay = SceneLayout.for_params(params)
    x = lay.vector(params)
    value, grad = scale.value_and_gradient(x)
    assert value == pytest.approx(scale.log_radius(x), abs=1e-14)
    s = lay.slices()
    moved = np.r_[s["shape"], s["expression"], s["angles"], s["translation"]]
    for i in range(lay.size):
        h = 1e-5 if i in moved else 1.0
        up, down = x.copy(), x.copy()
        up[i] += h
        down[i] -= h
        fd = (scale.log_radius(up) - scale.log_radius(down)) / (2 * h)
        assert grad[i] == pytest.approx(fd, rel=1e-5, abs=1e-10), lay_name(lay, i)
    assert np.all(grad[np.setdiff1d(np.arange(lay.size), moved)] == 0.0)


def lay_name(lay, i):
    for name, sl in lay.slices().items():
        if sl.start <= i < sl.stop:
            return f"{name}[{i - sl.start}]"
    return str(i)


def _coords(setting):
    _, params, _, scale = setting
    return SamplingCoordinates(SceneLayout.for_params(params), params, scale=scale)


def test_image_size_coordinate_round_trip_and_invariance(setting):
    _, params, _, scale = setting
    c = _coords(setting)
    names = list(c.names)
    assert "log_image_size" in names and "log_focal_length" not in names
    k, kd = names.index("log_image_size"), names.index("log_distance")
    u = c.u_of(params)
    x = c.layout.vector(params)
    assert u[k] == pytest.approx(math.log(params.camera.focal_length) + scale.log_radius(x))
    q = c.params_of(u + 0.01, params)
    np.testing.assert_allclose(c.u_of(q), u + 0.01, rtol=0, atol=1e-12)
    # the distance moves at a fixed image size: the focal length follows it (f / d nearly fixed)
    v = u.copy()
    v[kd] += 0.05
    far = c.params_of(v, params)
    ratio = far.camera.focal_length / params.camera.focal_length
    assert ratio == pytest.approx(math.exp(0.05), rel=0.02) and ratio != pytest.approx(
        math.exp(0.05), rel=1e-6)  # not exactly: the face's depth is not the model origin's
    x_far = c.layout.vector(far)
    assert math.log(far.camera.focal_length) + scale.log_radius(x_far) == pytest.approx(
        u[k], abs=1e-12)
    with pytest.raises(InputError):
        SamplingCoordinates(SceneLayout.for_params(params), params,
                            scale=ImageScale.of_model(small_face_model(subdivisions=3),
                                                      params._replace(momo=MoMoCoefficients.zeros(
                                                          3, 3, 2)), np.arange(10)))


def test_jacobian_log_determinant_and_gradient(setting):
    _, params, _, _ = setting
    c = _coords(setting)
    rng = np.random.default_rng(0)
    u = c.u_of(params) + rng.normal(0, 0.01, c.size)
    idx = c.scene_indices
    h = 1e-6
    jac = np.empty((c.size, c.size))
    for j in range(c.size):
        e = np.zeros(c.size)
        e[j] = h
        jac[:, j] = (c.x_of_u(u + e)[idx] - c.x_of_u(u - e)[idx]) / (2 * h)
    np.testing.assert_allclose(c.jacobian(u), jac, rtol=1e-5, atol=1e-7)
    sign, logdet = np.linalg.slogdet(jac)
    assert sign != 0 and c.log_jacobian(u) == pytest.approx(logdet, abs=1e-6)

    # a smooth log density in x: a quadratic plus a log-normal focal prior
    lay = c.layout
    f = lay.slices()["focal_length"].start
    a = rng.normal(0, 0.1, lay.size)
    x0 = c.x_of_u(u)

    def log_px(x):
        return float(a @ (x - x0) - 0.5 * np.sum((x - x0) ** 2)
                     - (math.log(x[f]) - 2.0) ** 2 / 0.32 - math.log(x[f]))

    def grad_px(x):
        g = a - (x - x0)
        g[f] += -(math.log(x[f]) - 2.0) / (0.16 * x[f]) - 1.0 / x[f]
        return g

    gu, pu = c.to_coordinates(grad_px(x0), np.eye(lay.size), u)
    eps = 1e-5
    for j in range(c.size):
        up, down = u.copy(), u.copy()
        up[j] += eps
        down[j] -= eps
        fd = ((log_px(c.x_of_u(up)) + c.log_jacobian(up))
              - (log_px(c.x_of_u(down)) + c.log_jacobian(down))) / (2 * eps)
        assert gu[j] == pytest.approx(fd, rel=1e-5, abs=1e-6), c.names[j]
    np.testing.assert_allclose(c.gradient(grad_px(x0), u), gu, rtol=1e-12, atol=1e-12)
    assert np.all(np.linalg.eigvalsh(0.5 * (pu + pu.T)) > 0)


def test_orthographic_camera_is_refused(setting):
    model, params, ids, _ = setting
    ortho = params._replace(camera=params.camera._replace(orthographic=True))
    with pytest.raises(InputError, match="perspective"):
        ImageScale.of_model(model, ortho, ids)


def test_outside_the_domain_is_nan_not_an_error(setting):
    """A face pushed behind the camera has no image size: NaN, so a move there is refused."""
    _, params, _, scale = setting
    c = _coords(setting)
    u = c.u_of(params)
    k = list(c.names).index("log_distance")
    near = u.copy()
    near[k] = math.log(20.0)  # 20 mm from the model origin: the face's front is behind the camera
    x = c.x_of_u(near)
    assert math.isnan(scale.log_radius(x)) and math.isnan(x[c.layout.slices()["focal_length"]][0])
    assert math.isnan(c.log_jacobian(near))
    value, grad = scale.value_and_gradient(x)
    assert math.isnan(value) and np.all(np.isnan(grad))
