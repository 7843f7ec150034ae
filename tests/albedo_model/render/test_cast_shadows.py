"""Cast shadows of the directional light: against a trimesh reference, and the rays each step casts.

The model is a sphere with a nose (a Gaussian ridge on its front, +z), so a side
light casts a real shadow of the nose on a cheek besides the attached shadow of
the far side. The reference visibility is computed here from the rendered
primary hits alone: the surface point of each face pixel from its triangle and
barycentrics, one occlusion ray towards the light through
``trimesh.Trimesh.ray.intersects_any``: trimesh's own scene and offsets (it runs on
its embreex backend when installed), none of the project's ray-casting code.
The model and scenes are :mod:`shadow_scenes`.
"""

from __future__ import annotations

import numpy as np
import pytest
from shadow_scenes import lit_scene, nosed_model, reference_occlusion, side_light

from albedo_model.camera import project
from albedo_model.params import Block, ColorTransform, DirectionalLight, SHLight
from albedo_model.render.cache_table import stage_key
from albedo_model.render.renderer import Renderer

#: |n . l| (flat triangle normal, unit light direction) below which a pixel is grazing:
#: the renderer and the reference may disagree there (different ray offsets).
GRAZING = 0.05
#: Fraction of face pixels on which the renderer and the reference must agree.
MIN_AGREEMENT = 0.99

# (yaw, light azimuth, light elevation) in degrees: side lights that shadow 29-35 %
# of the face, 1-6 % of it cast by the nose onto surface turned towards the light
SHADOW_SCENES = [(-30, -60, 15), (-10, -45, 30), (0, 45, 15), (20, 55, 15), (40, 65, 25)]


def reference_shadow(state, triangles):
    """Occlusion of the directional light at every face pixel of ``state``, cast with trimesh.

    Returns
    -------
    face : (F,) int
        Row-major image indices of the pixels whose primary ray hit the mesh.
    occluded : (F,) bool
        The mesh lies between the pixel's surface point and the light.
    n_dot_l : (F,) float
        Flat normal of the hit triangle dotted with the unit light direction (model frame).
    points : (F, 3) float
        The surface points (model frame).
    """
    face, occluded, n_dot_l, points = reference_occlusion(
        state, triangles, [state.params.directional_light.direction])
    return face, occluded[0], n_dot_l, points


def rendered_visibility(state) -> np.ndarray:
    """The state's cached shadow as a whole image (1 off the pixel set)."""
    return state.full(state.shadow[1], fill=1.0)


def assert_matches_reference(state, triangles):
    """Assert the state's shadow agrees with :func:`reference_shadow`; return statistics."""
    face, occluded, n_dot_l, _ = reference_shadow(state, triangles)
    shadowed = rendered_visibility(state)[face] == 0.0
    disagree = shadowed != occluded
    agreement = 1.0 - disagree.mean()
    assert agreement >= MIN_AGREEMENT, agreement
    assert np.all(np.abs(n_dot_l[disagree]) < GRAZING), n_dot_l[disagree]
    return face, occluded, n_dot_l, agreement


@pytest.mark.parametrize("yaw,azimuth,elevation", SHADOW_SCENES)
def test_cast_shadows_match_trimesh_reference(yaw, azimuth, elevation):
    """Shadows of a side light agree with an independent trimesh occlusion test.

    For each pose (yaw -30..40 deg) and side light (azimuth 45-70 deg either side,
    elevation 15-30 deg), the visibility ``Renderer(shadows=True)`` caches at its
    pixel set is compared with one trimesh occlusion ray per face pixel from the
    surface point its primary hit names (Embree barycentrics) towards the light
    in the model frame (``R.T @ d_world``). Checked against that reference:
    the surface points project onto their pixels (the barycentric convention),
    10-40 % of the face is shadowed and at least 0.5 % is cast shadow on
    surface facing the light (n . l > 0.1), so agreement is not vacuous; at
    least 99 % of the face pixels agree and every disagreement is grazing
    (|n . l| < 0.05). Measured: 29-35 % shadowed, 1.1-6.2 % cast, >= 99.87 % agree.
    """
    model = nosed_model()
    params = lit_scene(yaw, azimuth, elevation)
    state = Renderer(model, shadows=True).init_state(params)
    assert state.effects.shadows
    key, visibility = state.shadow
    assert key == stage_key(state.versions, "shadow")
    assert visibility.shape == (len(state.pixels),)
    assert set(np.unique(visibility)) <= {0.0, 1.0}

    face, occluded, n_dot_l, points = reference_shadow(state, model.triangles)
    pixels, _ = project(points, params.pose, params.view, params.camera, params.image_size)
    w = params.image_size.width
    np.testing.assert_allclose(pixels, np.column_stack([face % w, face // w]), atol=1e-2)
    assert 0.10 <= occluded.mean() <= 0.40, occluded.mean()
    assert (occluded & (n_dot_l > 0.1)).mean() >= 0.005

    assert_matches_reference(state, model.triangles)
    # pixels without a primary hit are never shadowed
    off_face = np.ones(len(state.hits.prim_id), bool)
    off_face[face] = False
    assert np.all(rendered_visibility(state)[off_face] == 1.0)


def test_shadowed_pixels_get_no_directional_diffuse():
    """Shadowed pixels are shaded as if the directional light were off.

    With the light's ambient and specular 0, the image at the pixels the state
    marks shadowed equals the image of the same scene without the directional
    light (``DirectionalLight()``); the comparison is not vacuous: the light
    brightens lit pixels facing it, and an unshadowed render
    (``Renderer(shadows=False)``) is brighter on >= 95 % of the nose's cast
    shadow (pixels whose flat normal faces the light, n . l > 0.1).
    """
    model = nosed_model()
    params = lit_scene(0, 45, 15)
    out = Renderer(model, shadows=True).render(params)
    state = out.state
    dark = Renderer(model, shadows=True).render(
        params._replace(directional_light=DirectionalLight())).image
    unshadowed = Renderer(model, shadows=False).render(params).image
    assert out.image.max() < 1.0  # no clamping hides a difference

    face, occluded, n_dot_l, _ = reference_shadow(state, model.triangles)
    h, w = out.mask.shape
    shadowed = np.zeros(h * w, bool)
    shadowed[face] = rendered_visibility(state)[face] == 0.0
    shadowed = shadowed.reshape(h, w)
    assert shadowed.sum() > 500
    np.testing.assert_allclose(out.image[shadowed], dark[shadowed], atol=1e-6)

    facing = np.zeros(h * w, bool)
    facing[face[~occluded & (n_dot_l > 0.3)]] = True
    facing = facing.reshape(h, w) & ~shadowed
    assert facing.sum() > 500
    assert np.all(out.image[facing] > dark[facing] + 0.02)
    cast = np.zeros(h * w, bool)
    cast[face[occluded & (n_dot_l > 0.1)]] = True
    cast = cast.reshape(h, w) & shadowed
    assert cast.sum() > 100
    # the shader's interpolated normal may still face away where the flat one does not
    gain = (unshadowed[cast] - out.image[cast]).min(axis=1)
    assert np.mean(gain > 1e-3) >= 0.95 and gain.mean() > 0.02


def test_shadows_of_a_shape_move_are_cast_against_the_proposed_geometry():
    """A shape step's shadow is cast against its own (spare-scene) geometry.

    Lengthening the nose (first shape component) moves its cast shadow; the
    proposed state's shadow agrees with the trimesh reference on the proposed
    shape, and differs from the start state's. After the step is accepted, a
    light-direction step casts against the accepted geometry (again checked
    against the reference); after a rejected one, the start state's shadow
    still matches the start geometry.
    """
    model = nosed_model()
    renderer = Renderer(model, shadows=True)
    params = lit_scene(0, 45, 15)
    state = renderer.init_state(params)
    m = params.momo
    longer = params._replace(momo=m._replace(shape=np.array([1.5, 0.0, 0.0])))
    cand = renderer.update(state, longer, Block.SHAPE)
    assert cand.geometry_pending
    assert_matches_reference(cand, model.triangles)
    before = rendered_visibility(state)
    after = rendered_visibility(cand)
    assert np.count_nonzero(before != after) > 20
    assert after.mean() < before.mean()  # a longer nose shadows more
    renderer.reject()
    relit = params._replace(directional_light=side_light(-55, 20))
    assert_matches_reference(renderer.update(state, relit, Block.DIRECTIONAL), model.triangles)

    state = renderer.accept(renderer.update(state, longer, Block.SHAPE))
    relit = longer._replace(directional_light=side_light(-55, 20))
    moved = renderer.update(state, relit, Block.DIRECTIONAL)
    assert_matches_reference(moved, model.triangles)
    np.testing.assert_allclose(renderer.image(moved).image,
                               Renderer(model, shadows=True).render(relit).image, atol=2e-5)


def _delta(renderer, before):
    return {k: renderer.ray_counts[k] - before[k] for k in renderer.ray_counts}


def test_steps_cast_only_the_rays_they_need():
    """``Renderer.ray_counts`` after each kind of step, against what the step changes.

    A light-direction step (``Block.DIRECTIONAL_ANGLES``) casts one shadow ray
    per face pixel and no primary ray, reuses the primary hits, and gives the
    image of a fresh render of the new parameters; SH light, albedo, colour and
    directional-strength steps cast nothing and keep the very shadow array of
    the state they start from; a pose
    step casts both, and the steps after it is accepted reuse its shadow.
    """
    model = nosed_model()
    renderer = Renderer(model, shadows=True)
    params = lit_scene(20, 55, 15)
    state = renderer.init_state(params)
    n_face = int(np.count_nonzero(state.hits.prim_id >= 0))
    assert renderer.ray_counts["shadow"] == n_face
    assert renderer.ray_counts["primary"] >= n_face

    before = dict(renderer.ray_counts)
    turned = params._replace(directional_light=side_light(-50, 25))
    cand = renderer.update(state, turned, Block.DIRECTIONAL_ANGLES)
    assert _delta(renderer, before) == {"primary": 0, "shadow": n_face}
    assert cand.hits is state.hits and cand.pixel_hits is state.pixel_hits
    assert cand.shadow is not state.shadow and cand.shadow[0] != state.shadow[0]
    np.testing.assert_allclose(renderer.image(cand).image,
                               Renderer(model, shadows=True).render(turned).image, atol=2e-5)
    renderer.reject()

    m = params.momo
    unchanged = {
        Block.LIGHT: params._replace(environment_map=SHLight(
            params.environment_map.coefficients * 0.7)),
        Block.ALBEDO: params._replace(momo=m._replace(albedo=m.albedo + [0.5, -0.3, 0.2])),
        Block.COLOR_TRANSFORM: params._replace(
            color_transform=ColorTransform((1.1, 0.9, 1.0), 0.8, (0.01, 0.0, 0.0))),
        Block.DIRECTIONAL_STRENGTH: params._replace(directional_light=params.directional_light
                                                    ._replace(diffuse=(0.3, 0.5, 0.4),
                                                              specular=(0.3, 0.5, 0.4))),
    }
    for touched, moved in unchanged.items():
        before = dict(renderer.ray_counts)
        cand = renderer.update(state, moved, touched)
        assert _delta(renderer, before) == {"primary": 0, "shadow": 0}, touched
        assert cand.shadow is state.shadow, touched
        np.testing.assert_allclose(renderer.image(cand).image,
                                   Renderer(model, shadows=True).render(moved).image, atol=2e-5)
        renderer.reject()

    before = dict(renderer.ray_counts)
    posed = params._replace(pose=params.pose._replace(yaw=params.pose.yaw - 0.3))
    cand = renderer.update(state, posed, Block.POSE)
    delta = _delta(renderer, before)
    assert delta["primary"] > 0
    assert delta["shadow"] == np.count_nonzero(cand.hits.prim_id >= 0)
    assert cand.shadow is not state.shadow
    assert_matches_reference(cand, model.triangles)
    np.testing.assert_allclose(renderer.image(cand).image,
                               Renderer(model, shadows=True).render(posed).image, atol=2e-5)
    state = renderer.accept(cand)
    before = dict(renderer.ray_counts)
    lit = renderer.update(state, unchanged[Block.LIGHT]._replace(pose=posed.pose), Block.LIGHT)
    assert _delta(renderer, before) == {"primary": 0, "shadow": 0}
    assert lit.shadow is state.shadow


def test_no_shadow_rays_without_a_directional_light():
    """With the directional light off, ``Renderer(shadows=True)`` casts no shadow ray.

    Checked on a full render, on SH light and pose steps, and with
    ``shadows=False`` and the light on. A light-direction step that switches the
    light on casts one shadow ray per face pixel and matches a fresh render; one
    that switches it off again casts none and drops the shadow.
    """
    model = nosed_model()
    params = lit_scene(0, 45, 15)
    dark = params._replace(directional_light=DirectionalLight())
    renderer = Renderer(model, shadows=True)
    state = renderer.init_state(dark)
    assert renderer.ray_counts["shadow"] == 0 and renderer.ray_counts["primary"] > 0
    assert not state.effects.shadows and state.shadow is None
    dimmer = SHLight(dark.environment_map.coefficients * 0.7)
    for touched, moved in [
        (Block.LIGHT, dark._replace(environment_map=dimmer)),
        (Block.POSE, dark._replace(pose=dark.pose._replace(yaw=0.4))),
    ]:
        renderer.update(state, moved, touched)
        renderer.reject()
    assert renderer.ray_counts["shadow"] == 0

    unshadowed = Renderer(model, shadows=False)
    unshadowed.render(params)
    assert unshadowed.ray_counts["shadow"] == 0 and unshadowed.ray_counts["primary"] > 0

    n_face = int(np.count_nonzero(state.hits.prim_id >= 0))
    before = dict(renderer.ray_counts)
    on = renderer.accept(renderer.update(state, params, Block.DIRECTIONAL))
    assert _delta(renderer, before) == {"primary": 0, "shadow": n_face}
    assert on.effects.shadows
    np.testing.assert_allclose(renderer.image(on).image,
                               Renderer(model, shadows=True).render(params).image, atol=2e-5)
    before = dict(renderer.ray_counts)
    off = renderer.update(on, dark, Block.DIRECTIONAL)
    assert _delta(renderer, before) == {"primary": 0, "shadow": 0}
    assert off.shadow is None
    np.testing.assert_allclose(renderer.image(off).image, renderer.image(state).image, atol=2e-5)
