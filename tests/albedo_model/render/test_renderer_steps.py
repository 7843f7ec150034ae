"""Renderer steps: cached block updates against a full re-render, reject and accept.

Also likelihoods fused with shading (compose), reused per-pixel caches and
pixel sets. Model and scenes: renderer_scenes.py.
"""

from __future__ import annotations

import numpy as np
import pytest
from renderer_scenes import bumpy_model, moves, scene

from albedo_model.params import Block, MoMoCoefficients, SHLight
from albedo_model.render.renderer import Renderer


def test_cached_update_equals_full_render_and_reject_restores():
    model = bumpy_model()
    rng = np.random.default_rng(1)
    renderer = Renderer(model, gamma=True)
    state = renderer.init_state(scene(sh=SHLight.frontal()))
    before = renderer.image(state).image
    for touched, params in moves(state.params, rng):
        cand = renderer.update(state, params, touched)
        fresh = Renderer(model, gamma=True).render(params)
        np.testing.assert_allclose(renderer.image(cand).image, fresh.image, atol=2e-5)
        # untouched blocks are bit-identical
        if not touched & (Block.SHAPE | Block.EXPRESSION | Block.POSE | Block.CAMERA):
            assert cand.prim_id is state.prim_id
        if not touched & Block.ALBEDO:
            assert cand.diffuse is state.diffuse
        renderer.reject()
        np.testing.assert_array_equal(renderer.image(state).image, before)
    # accept a shape move, then a pose move casts with the accepted geometry
    m = state.params.momo
    shape_params = state.params._replace(momo=m._replace(shape=np.array([1.0, 1.0])))
    state = renderer.accept(renderer.update(state, shape_params, Block.SHAPE))
    pose_params = shape_params._replace(pose=shape_params.pose._replace(yaw=0.9))
    cand = renderer.update(state, pose_params, Block.POSE)
    np.testing.assert_allclose(renderer.image(cand).image,
                               Renderer(model, gamma=True).render(pose_params).image, atol=2e-5)


def test_compose_fuses_shading_with_a_function():
    import jax.numpy as jnp
    model = bumpy_model()
    renderer = Renderer(model, gamma=True)
    state = renderer.init_state(scene(sh=SHLight.frontal()))
    target = tuple(jnp.full(state.hits.prim_id.shape, 0.3 + 0.1 * c, jnp.float32) for c in range(3))

    def sq_error(rgb, mask, target, scale):
        sq = sum((rgb[c] - target[c]) ** 2 for c in range(3))
        return scale * jnp.sum(jnp.where(mask, sq, 0.0)), jnp.sum(mask)

    fused = renderer.compose(sq_error)
    got, count = fused(state, target, jnp.float32(2.0))
    out = renderer.image(state)
    want = 2.0 * sum(((out.image[..., c] - (0.3 + 0.1 * c)) ** 2)[out.mask].sum() for c in range(3))
    assert float(got) == pytest.approx(want, rel=1e-5)
    assert int(count) == out.mask.sum()


def test_likelihood_of_a_step_fuses_the_attributes_it_changed():
    """compose() evaluates a proposal's new pixel attributes inside its own program, stores
    none of them, and gives the value of the stored attributes; an accepted state computes
    them when a later step reads them."""
    import jax.numpy as jnp
    model = bumpy_model()
    renderer = Renderer(model, gamma=True)
    state = renderer.init_state(scene(sh=SHLight.frontal()))
    target = tuple(jnp.full(state.hits.prim_id.shape, 0.3 + 0.1 * c, jnp.float32) for c in range(3))

    def sq_error(rgb, mask, target):
        return sum(jnp.sum(jnp.where(mask, (rgb[c] - target[c]) ** 2, 0.0)) for c in range(3))

    def reference(out):
        return sum(((out.image[..., c] - (0.3 + 0.1 * c)) ** 2)[out.mask].sum() for c in range(3))

    def caches(s):
        return s.pixel_hits, s.pixel_geometry, s.pixel_albedo, s.pixel_light

    fused = renderer.compose(sq_error)
    rng = np.random.default_rng(4)
    for touched, params in moves(state.params, rng):
        cand = renderer.update(state, params, touched)
        got = float(fused(cand, target))
        new = [c for c, old in zip(caches(cand), caches(state)) if c is not old]
        assert not any(c.computed for c in new), touched
        assert got == pytest.approx(reference(renderer.image(cand)), rel=1e-5)
        assert all(c.computed for c in caches(cand))  # image() read them
        renderer.reject()
    # accept a shape step whose attributes were only fused, then step the light
    m = state.params.momo
    shaped = state.params._replace(momo=m._replace(shape=m.shape + 0.5))
    cand = renderer.update(state, shaped, Block.SHAPE)
    float(fused(cand, target))
    state = renderer.accept(cand)
    lit = shaped._replace(environment_map=SHLight(shaped.environment_map.coefficients * 0.8))
    got = float(fused(renderer.update(state, lit, Block.LIGHT), target))
    assert state.pixel_geometry.computed and state.pixel_albedo.computed
    assert got == pytest.approx(reference(Renderer(model, gamma=True).render(lit)), rel=1e-5)


def test_steps_reuse_cached_pixel_attributes():
    model = bumpy_model()
    renderer = Renderer(model)
    state = renderer.init_state(scene(sh=SHLight.frontal()))
    rng = np.random.default_rng(2)
    moved = dict(moves(state.params, rng))
    light = renderer.update(state, moved[Block.LIGHT], Block.LIGHT)
    assert light.pixel_geometry is state.pixel_geometry and light.pixel_albedo is state.pixel_albedo
    assert light.pixel_light is not state.pixel_light
    albedo = renderer.update(state, moved[Block.ALBEDO], Block.ALBEDO)
    assert albedo.pixel_hits is state.pixel_hits and albedo.pixel_geometry is state.pixel_geometry
    assert albedo.pixel_albedo is not state.pixel_albedo
    assert albedo.pixel_light is state.pixel_light  # an albedo step evaluates no light
    colour = renderer.update(state, moved[Block.COLOR_TRANSFORM], Block.COLOR_TRANSFORM)
    assert colour.pixel_light is state.pixel_light and colour.pixel_albedo is state.pixel_albedo
    pose = renderer.update(state, moved[Block.POSE], Block.POSE)
    assert pose.pixel_geometry is not state.pixel_geometry and pose.shape is state.shape


def test_long_chain_of_block_updates_matches_full_render():
    """Hundreds of accepted float32 block updates (with periodic refresh) stay exact."""
    model = bumpy_model(k=6)
    renderer = Renderer(model, gamma=True)
    renderer._instances.updater.refresh_every = 64
    start = scene(sh=SHLight.frontal())
    start = start._replace(momo=MoMoCoefficients(np.full(6, 0.1), np.full(6, -0.1), np.zeros(0)))
    state = renderer.init_state(start)
    rng = np.random.default_rng(3)
    for step in range(300):
        m = state.params.momo
        block = slice(2 * (step % 3), 2 * (step % 3) + 2)
        if step % 2:
            c = m.albedo.copy()
            c[block] += rng.normal(0, 0.2, 2)
            p, touched = state.params._replace(momo=m._replace(albedo=c)), Block.ALBEDO
        else:
            c = m.shape.copy()
            c[block] += rng.normal(0, 0.05, 2)
            p, touched = state.params._replace(momo=m._replace(shape=c)), Block.SHAPE
        state = renderer.accept(renderer.update(state, p, touched))
    assert state.updates == (150 % 64, 150 % 64)  # 150 updates each, refreshed every 64
    fresh = Renderer(model, gamma=True).render(state.params)
    np.testing.assert_allclose(renderer.image(state).image, fresh.image, atol=3e-5)
    np.testing.assert_allclose(state.shape, model.shape.instance(state.params.momo.shape),
                               atol=1e-4)
    c = state.params.momo.albedo
    np.testing.assert_allclose(state.diffuse, model.diffuse.instance(c), atol=1e-5)
    np.testing.assert_allclose(state.specular, model.specular.instance(c), atol=1e-5)


def test_light_change_that_switches_effects_on():
    """A DIRECTIONAL step adding a directional light needs view directions the cache lacked."""
    from albedo_model.params import DirectionalLight
    model = bumpy_model()
    renderer = Renderer(model, specular=False)
    state = renderer.init_state(scene(sh=SHLight.frontal()))
    assert state.pixel_geometry.view is None
    lit = state.params._replace(directional_light=DirectionalLight(
        (0.1,) * 3, (0.6,) * 3, (0.3, 0.4, 1.0), (0.3,) * 3, 15.0))
    cand = renderer.update(state, lit, Block.DIRECTIONAL)
    assert cand.effects.directional and cand.pixel_geometry.view is not None
    np.testing.assert_allclose(renderer.image(cand).image,
                               Renderer(model, specular=False).render(lit).image, atol=2e-5)


def test_albedo_steps_with_independent_specular_albedo():
    """Without shared coefficients only the diffuse row moves; the specular stays its mean."""
    import dataclasses
    shared = bumpy_model()
    model = dataclasses.replace(shared, shared_albedo=False)
    renderer = Renderer(model, gamma=True)
    state = renderer.init_state(scene(sh=SHLight.frontal()))
    m = state.params.momo
    for step in range(3):
        c = m.albedo.copy()
        c[step % 3] += 0.7
        p = state.params._replace(momo=m._replace(albedo=c))
        state = renderer.accept(renderer.update(state, p, Block.ALBEDO))
        m = state.params.momo
    np.testing.assert_allclose(state.specular, model.specular.mean, atol=1e-6)
    np.testing.assert_allclose(state.diffuse, model.diffuse.instance(m.albedo), atol=1e-5)
    np.testing.assert_allclose(renderer.image(state).image,
                               Renderer(model, gamma=True).render(state.params).image, atol=2e-5)


def test_rays_are_reused_only_for_the_same_camera_and_pose():
    """A shape step keeps the last rays; poses with array fields are compared safely."""
    model = bumpy_model()
    renderer = Renderer(model)
    params = scene(sh=SHLight.frontal())
    params = params._replace(pose=params.pose._replace(translation=np.array([4.0, -3.0, -700.0])))
    state = renderer.init_state(params)
    m = params.momo
    shaped = params._replace(momo=m._replace(shape=m.shape + 0.5))
    cand = renderer.update(state, shaped, Block.SHAPE)
    np.testing.assert_allclose(renderer.image(cand).image,
                               Renderer(model).render(shaped).image, atol=2e-5)
    renderer.reject()
    turned = params._replace(pose=params.pose._replace(yaw=0.5))
    np.testing.assert_allclose(renderer.image(renderer.update(state, turned, Block.POSE)).image,
                               Renderer(model).render(turned).image, atol=2e-5)


def test_pixel_set_holds_every_hit_and_compose_on_it_matches_the_whole_image():
    """The caches hold the hit pixels plus a few misses (a multiple of the width); a
    likelihood on that set equals the one on the whole image, step after step."""
    import jax.numpy as jnp
    model = bumpy_model()
    renderer = Renderer(model, gamma=True)
    state = renderer.init_state(scene(sh=SHLight.frontal()))
    w, h = state.params.image_size
    pixels = state.pixels
    assert pixels is not None and len(pixels) % w == 0 and len(pixels) < w * h
    assert np.all(np.diff(pixels) > 0)
    assert set(np.flatnonzero(state.hits.mask)) <= set(pixels)
    np.testing.assert_array_equal(state.full(state.pixel_hits.mask, False), state.hits.mask)
    target = tuple(jnp.full(w * h, 0.3 + 0.1 * c, jnp.float32) for c in range(3))

    def sq_error_on_set(rgb, mask, pixels, target):
        at = target if pixels is None else tuple(t[pixels] for t in target)
        return sum(jnp.sum(jnp.where(mask, (rgb[c] - at[c]) ** 2, 0.0)) for c in range(3))

    def reference(out):
        return sum(((out.image[..., c] - (0.3 + 0.1 * c)) ** 2)[out.mask].sum() for c in range(3))

    fused = renderer.compose(sq_error_on_set, pixel_set=True)
    assert float(fused(state, target)) == pytest.approx(reference(renderer.image(state)), rel=1e-5)
    rng = np.random.default_rng(7)
    for touched, params in moves(state.params, rng):
        cand = renderer.update(state, params, touched)
        got = float(fused(cand, target))
        assert got == pytest.approx(reference(renderer.image(cand)), rel=1e-5), touched
        renderer.reject()
    # a face filling the image: the set is every pixel (None), in image order
    close = state.params._replace(pose=state.params.pose._replace(
        translation=(0.0, 0.0, 0.35 * state.params.pose.translation[2])))
    full = renderer.init_state(close)
    assert full.hits.mask.mean() > 15 / 16 and full.pixels is None
    assert float(fused(full, target)) == pytest.approx(reference(renderer.image(full)), rel=1e-5)
