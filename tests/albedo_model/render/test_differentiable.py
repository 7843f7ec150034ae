"""Differentiable re-rendering at fixed hits: against the renderer's image and its differences.

Uses the small face model of ``tests/mcmcfit/face_factory.py`` (shape, expression,
specular and albedo parts on an ellipsoid head with a nose).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from face_factory import scene, small_face_model

from albedo_model.errors import InputError
from albedo_model.params import ColorTransform, DirectionalLight, MoMoCoefficients, SHLight
from albedo_model.render.differentiable import (
    DifferentiableModel,
    GeometryParams,
    build_value_and_grad,
    fixed_hits,
    geometry_params,
    pixel_colours,
    shade_attributes,
)
from albedo_model.render.renderer import Renderer

SIZE = 64


@pytest.fixture(scope="module")
def model():
    return small_face_model(subdivisions=4)


def _scene(seed: int, *, yaw=0.3, orthographic=False, identity_colour=False):
    rng = np.random.default_rng(seed)
    coeffs = MoMoCoefficients(rng.normal(size=4), rng.normal(size=3), rng.normal(size=2))
    p = scene(SIZE, SIZE, yaw=yaw, pitch=-0.1, roll=0.05, translation=(5.0, -3.0, -900.0),
              coefficients=coeffs)
    light = SHLight(SHLight.frontal().coefficients + rng.normal(0, 0.05, (9, 3)))
    ct = ColorTransform() if identity_colour else ColorTransform((1.1, 0.9, 1.0), 0.9,
                                                                 (0.01, 0.0, -0.01))
    cam = p.camera._replace(principal_point=(0.03, -0.02), orthographic=orthographic)
    if orthographic:  # the near plane sets the orthographic scale: the head fills the image
        cam = cam._replace(near=600.0, focal_length=6.0)
    return p._replace(environment_map=light, color_transform=ct, camera=cam,
                      specular_exponent=float(rng.uniform(10, 30)))


def _colours(dm: DifferentiableModel, params, prim_id, dtype=np.float32):
    hits, _ = fixed_hits(prim_id, SIZE, SIZE)
    effects, ortho = dm.effects(params), bool(params.camera.orthographic)
    fn = jax.jit(lambda g, s, h: pixel_colours(effects, ortho, g, s, h))
    rgb, mask = fn(geometry_params(params, dtype), dm.scene(params, dtype),
                   hits._replace(pixels=None))
    return hits, np.stack([np.asarray(c) for c in rgb], 1), np.asarray(mask)


@pytest.mark.parametrize("seed,yaw,specular,orthographic", [
    (0, 0.3, True, False), (1, -0.6, True, False), (2, 0.0, False, False), (3, 0.4, True, True)])
def test_colours_at_the_cast_parameters_equal_the_renderer_image(model, seed, yaw, specular,
                                                                  orthographic):
    params = _scene(seed, yaw=yaw, orthographic=orthographic)
    renderer = Renderer(model, specular=specular, threads=1)
    out = renderer.render(params)
    dm = DifferentiableModel(model, specular=specular)
    assert dm.effects(params) == renderer.effects(params)
    hits, rgb, mask = _colours(dm, params, out.state.prim_id)
    np.testing.assert_array_equal(mask, out.mask.reshape(-1)[hits.pixels])
    assert mask.sum() > 800
    ref = out.image.reshape(-1, 3)[hits.pixels]
    np.testing.assert_allclose(rgb[mask], ref[mask], rtol=0, atol=2e-5)


def _random_geometry(rng, params, dtype=np.float64) -> GeometryParams:
    """A random direction in the geometry parameters, scaled to a comparable effect each."""
    g = geometry_params(params, dtype)
    return GeometryParams(rng.normal(size=g.shape.shape), rng.normal(size=g.expression.shape),
                          rng.normal(0, 0.05, 3), rng.normal(0, 5.0, 3),
                          np.asarray(rng.normal(0, 0.1)))


def _readout(rgb, mask, weights):
    """A random linear read-out of the colours (value, no aux)."""
    return sum(jnp.sum(jnp.where(mask, w * c, 0.0)) for w, c in zip(weights, rgb)), None


def _entries(geo: GeometryParams) -> np.ndarray:
    return np.concatenate([np.ravel(a) for a in geo])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_gradient_matches_central_differences_of_the_same_function(model, seed):
    """float64: the gradient of a random linear read-out of the colours vs central differences."""
    params = _scene(seed, yaw=0.3)  # one view: the same compiled programs for every seed
    prim = Renderer(model, threads=1).render(params).state.prim_id
    dm = DifferentiableModel(model)
    rng = np.random.default_rng(10 + seed)
    with jax.enable_x64(True):
        hits, _ = fixed_hits(prim, SIZE, SIZE)
        scene64 = dm.scene(params, np.float64)
        effects = dm.effects(params)
        weights = [jnp.asarray(rng.normal(size=len(hits.pixels))) for _ in range(3)]

        def value(geo):
            return _readout(*pixel_colours(effects, False, geo, scene64, hits), weights)[0]

        f = jax.jit(value)
        geo = GeometryParams(*(jnp.asarray(a) for a in geometry_params(params, np.float64)))
        # the staged gradient the posterior uses (build_value_and_grad), against differences
        _, grad = build_value_and_grad(effects, False, _readout)(geo, scene64, hits, weights)
        grad = _entries(grad)
        flat = _entries(geo)
        sizes = [np.size(a) for a in geo]

        def at(x):
            parts = np.split(x, np.cumsum(sizes)[:-1])
            return GeometryParams(*(jnp.asarray(q.reshape(np.shape(a)))
                                    for q, a in zip(parts, geo)))

        fd = np.empty_like(flat)
        for i in range(flat.size):
            h = 1e-6 * max(1.0, abs(flat[i]))
            up, down = flat.copy(), flat.copy()
            up[i] += h
            down[i] -= h
            fd[i] = (float(f(at(up))) - float(f(at(down)))) / (2 * h)
    assert np.all(np.abs(grad) > 0)  # every parameter moves some pixel
    np.testing.assert_allclose(grad, fd, rtol=1e-5, atol=1e-6 * np.abs(grad).max())


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_derivative_matches_differences_of_the_renderer_image(model, seed):
    """A small step along a random direction: pixels keeping their triangle change as the JVP."""
    params = _scene(seed, yaw=0.4 * (seed - 1))
    renderer = Renderer(model, threads=1)
    base = renderer.render(params).state
    dm = DifferentiableModel(model)
    rng = np.random.default_rng(20 + seed)
    direction = _random_geometry(rng, params)
    hits, _ = fixed_hits(base.prim_id, SIZE, SIZE)
    effects = dm.effects(params)
    with jax.enable_x64(True):
        scene64 = dm.scene(params, np.float64)
        geo = GeometryParams(*(jnp.asarray(a) for a in geometry_params(params, np.float64)))
        _, jvp = jax.jvp(lambda g: pixel_colours(effects, False, g, scene64, hits)[0], (geo,),
                         (GeometryParams(*(jnp.asarray(a) for a in direction)),))
        jvp = np.stack([np.asarray(c) for c in jvp], 1)
    h = 0.02  # vertices move ~0.1 mm; float32 images resolve ~1e-7
    images, prims = [], []
    for sign in (1.0, -1.0):
        g = geometry_params(params, np.float64)
        moved = GeometryParams(*(a + sign * h * d for a, d in zip(g, direction)))
        p = params._replace(
            momo=params.momo._replace(shape=moved.shape, expression=moved.expression),
            pose=params.pose._replace(yaw=float(moved.angles[0]), pitch=float(moved.angles[1]),
                                      roll=float(moved.angles[2]),
                                      translation=tuple(float(t) for t in moved.translation)),
            camera=params.camera._replace(focal_length=float(moved.focal_length)))
        out = renderer.render(p)
        images.append(out.image.reshape(-1, 3)[hits.pixels].astype(np.float64))
        prims.append(out.state.prim_id[hits.pixels])
    prim0 = base.prim_id[hits.pixels]
    same = (prim0 >= 0) & (prims[0] == prim0) & (prims[1] == prim0)
    fd = (images[0] - images[1]) / (2 * h)
    assert same.mean() > 0.5 and same.sum() > 500
    err = np.abs(fd[same] - jvp[same])
    scale = np.abs(jvp[same]).max()
    # measured: median 4e-6..7e-6, 99 % 3e-5..8e-5 of the largest derivative
    assert np.median(err) < 1e-4 * scale, (np.median(err), scale)
    assert np.quantile(err, 0.99) < 2e-3 * scale, (np.quantile(err, 0.99), scale)


def test_shadows_are_refused(model):
    params = _scene(0)._replace(directional_light=DirectionalLight(diffuse=(0.5, 0.5, 0.5)))
    dm = DifferentiableModel(model)
    effects = dm.effects(params)._replace(shadows=True)
    hits, _ = fixed_hits(np.full(SIZE * SIZE, -1, np.int32), SIZE, SIZE)
    with pytest.raises(InputError):
        shade_attributes(effects, None, dm.scene(params), hits)
