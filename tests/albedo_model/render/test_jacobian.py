"""The pixel Jacobian in every continuous scene parameter: colours, forward mode, reverse mode.

Against the renderer's image (the colours), central differences of the colours
at fixed triangles (every column), and the Jacobian itself (the reverse-mode
gradient of a Gaussian read-out). Small face model of ``face_factory``.
"""

from __future__ import annotations

import numpy as np
import pytest
from face_factory import scene, small_face_model

from albedo_model.errors import InputError
from albedo_model.params import ColorTransform, DirectionalLight, MoMoCoefficients, SHLight
from albedo_model.render.differentiable import fixed_hits
from albedo_model.render.jacobian import PixelJacobian
from albedo_model.render.renderer import Renderer
from albedo_model.scene_vector import ENTRIES, SceneLayout

SIZE = 56
#: Central-difference step of each entry (its scale in a fit).
STEPS = {"angles": 1e-3, "translation": 0.05, "focal_length": 1e-3, "principal_point": 1e-4,
         "specular_exponent": 0.1, "light_angles": 1e-3}


@pytest.fixture(scope="module")
def model():
    return small_face_model(subdivisions=4)


def _params(seed=0):
    rng = np.random.default_rng(seed)
    p = scene(SIZE, SIZE, yaw=0.25, pitch=-0.1, roll=0.05, translation=(4.0, -2.0, -950.0),
              coefficients=MoMoCoefficients(rng.normal(size=4), rng.normal(size=3),
                                            rng.normal(size=2)))
    return p._replace(environment_map=SHLight(SHLight.frontal().coefficients
                                              + rng.normal(0, 0.05, (9, 3))),
                      color_transform=ColorTransform((1.05, 0.95, 1.0), 0.9, (0.01, 0.0, -0.01)),
                      camera=p.camera._replace(principal_point=(0.02, -0.01)),
                      specular_exponent=18.0)


def _hits(model, params):
    state = Renderer(model, specular=True, threads=1).init_state(params)
    hits, _ = fixed_hits(state.prim_id, SIZE, SIZE)
    return hits, state


def test_layout_round_trip():
    p = _params()
    lay = SceneLayout.for_params(p)
    assert tuple(lay.sizes()) == ENTRIES and lay.size == 4 + 2 + 3 + 3 + 1 + 2 + 27 + 3 + 1 + 3 + 1 + 3
    x = lay.vector(p)
    q = lay.with_vector(p, x + 0.01)
    np.testing.assert_allclose(lay.vector(q), x + 0.01, rtol=0, atol=1e-12)
    assert q.view == p.view and q.image_size == p.image_size
    with pytest.raises(InputError):
        lay.with_vector(p, x[:-1])


def test_colours_are_the_renderers(model):
    p = _params()
    hits, state = _hits(model, p)
    pj = PixelJacobian(model, SceneLayout.for_params(p))
    colours = pj.colours(p, hits)
    image = Renderer(model, specular=True, threads=1).image(state).image.reshape(-1, 3)
    m = np.asarray(hits.mask)
    np.testing.assert_allclose(colours[:, m].T, image[hits.pixels[m]], atol=5e-5)


def _jacobian(model, seed):
    p = _params(seed)
    hits, _ = _hits(model, p)
    lay = SceneLayout.for_params(p)
    pj = PixelJacobian(model, lay)
    return p, hits, lay, pj, *pj.jacobian(p, hits)


def _check_columns(pj, lay, p, hits, jac, names) -> None:
    """Assert that the Jacobian's columns of the entries ``names`` match central differences."""
    m = np.asarray(hits.mask)
    x = lay.vector(p)
    for name in names:
        sl = lay.slices()[name]
        h = STEPS.get(name, 1e-2)
        for i in range(sl.start, sl.stop):
            up, down = x.copy(), x.copy()
            up[i] += h
            down[i] -= h
            fd = (pj.colours(lay.with_vector(p, up), hits)
                  - pj.colours(lay.with_vector(p, down), hits)) / (2 * h)
            scale = max(np.abs(fd[:, m]).max(), 1e-6)
            err = np.abs(fd[:, m] - jac[:, m, i])
            # float32 differences and clamped channels: 99 % of pixels within 1 % of the column
            assert np.quantile(err, 0.99) < 0.01 * scale + 1e-4, (name, i)


def test_every_column_matches_central_differences(model):
    p, hits, lay, pj, _, jac = _jacobian(model, 1)
    _check_columns(pj, lay, p, hits, jac, lay.slices())


def test_reverse_mode_gradient_is_the_jacobian_transpose(model):
    p, hits, _, pj, colours, jac = _jacobian(model, 2)
    rng = np.random.default_rng(0)
    target = (colours + rng.normal(0, 0.02, colours.shape)).astype(np.float32)
    weight = np.where(np.asarray(hits.mask), 400.0, 0.0).astype(np.float32)
    value, grad = pj.gaussian_value_and_grad(p, hits, target, weight)
    r = colours - target
    assert value == pytest.approx(-0.5 * float(np.sum(weight * r * r)), rel=1e-4)
    expected = -np.einsum("cp,cpd->d", weight * r, jac.astype(np.float64))
    np.testing.assert_allclose(grad, expected, rtol=2e-3, atol=2e-3 * np.abs(expected).max())


def test_more_coefficients_than_the_model_is_an_error(model):
    with pytest.raises(InputError):
        PixelJacobian(model, SceneLayout(10, 2, 9, 3))


def _directional(model, seed: int):
    """A scene with a side light (on), its renderer state with cast shadows and its fixed hits."""
    p = _params(seed)._replace(directional_light=DirectionalLight.from_angles(
        0.9, 0.3, (0.7, 0.6, 0.5), shininess=20.0))
    r = Renderer(model, specular=True, shadows=True, directional_specular_map=True,
                 threads=1)
    state = r.init_state(p)
    hits, _ = fixed_hits(state.prim_id, SIZE, SIZE)
    shadow = state.full(state.shadow[1], fill=1.0)[hits.pixels]
    return p, r, state, hits._replace(shadow=shadow)


def test_directional_light_layout_colours_and_every_column(model):
    """A directional light with cast shadows: its five entries, the renderer's colours, every column.

    The shadow is the renderer's (held fixed); the light's azimuth, elevation
    and strengths are differentiated like the other entries (central differences).
    """
    p, r, state, hits = _directional(model, 3)
    assert 0.02 < 1.0 - float(np.mean(np.asarray(state.shadow[1])[np.asarray(
        state.pixel_hits.mask)])) < 0.6  # some pixels are in cast shadow
    lay = SceneLayout.for_params(p)
    assert lay.directional and lay.sizes()["light_angles"] == 2
    x = lay.vector(p)
    np.testing.assert_allclose(lay.vector(lay.with_vector(p, x)), x, atol=1e-9)
    pj = PixelJacobian(model, lay, shadows=True, directional_specular_map=True)
    m = np.asarray(hits.mask)
    image = r.image(state).image.reshape(-1, 3)
    colours, jac = pj.jacobian(p, hits)
    np.testing.assert_allclose(colours[:, m].T, image[hits.pixels[m]], atol=5e-5)
    _check_columns(pj, lay, p, hits, jac, ("light_angles", "light_intensity", "angles", "shape"))
    outside = x.copy()
    outside[lay.slices()["light_angles"].start + 1] = 1.7  # beyond the pole: off the chart
    assert np.isnan(lay.with_vector(p, outside).directional_light.diffuse[0])
