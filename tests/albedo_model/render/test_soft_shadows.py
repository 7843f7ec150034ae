"""Soft shadow edges: a few shadow rays per pixel over the light's disc, against trimesh.

The scenes and the model are ``shadow_scenes``' (a sphere with a nose under
a side light). The reference casts, with trimesh, one occlusion ray
per face pixel for each of the directions :func:`shadow_directions` gives and
averages them: the renderer's soft visibility must be that fraction.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from shadow_scenes import lit_scene, nosed_model, reference_occlusion, side_light

from albedo_model.errors import InputError
from albedo_model.params import Block
from albedo_model.render.renderer import Renderer
from albedo_model.render.visibility import shadow_directions
from mcmcfit.fitting.config import FitConfig

RAYS = 8
SPREAD_DEG = 6.0


def _delta(renderer, before):
    return {k: renderer.ray_counts[k] - before[k] for k in renderer.ray_counts}


def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    cos = np.clip(a @ b / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b)), -1.0, 1.0)
    return np.degrees(np.arccos(cos))


def test_shadow_directions_cover_the_light_disc_deterministically():
    """One ray is the centre; K rays are unit, inside the disc, spread over it, repeatable."""
    d = np.array([0.6, 0.3, 0.74])
    np.testing.assert_allclose(shadow_directions(d), [d / np.linalg.norm(d)], atol=1e-12)
    dirs = shadow_directions(d, RAYS, SPREAD_DEG)
    assert dirs.shape == (RAYS, 3)
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1.0, atol=1e-12)
    angles = _angle_deg(dirs, d)
    assert angles.max() <= SPREAD_DEG + 1e-9
    assert angles.max() >= 0.8 * SPREAD_DEG  # the rays reach the disc's rim
    assert len(np.unique(np.round(dirs, 9), axis=0)) == RAYS
    # centred: the mean direction is within a tenth of the radius of the light's centre
    assert _angle_deg(dirs.mean(axis=0), d) < 0.1 * SPREAD_DEG
    np.testing.assert_array_equal(dirs, shadow_directions(d, RAYS, SPREAD_DEG))
    with pytest.raises(InputError, match="shadow rays"):
        shadow_directions(d, 0, SPREAD_DEG)


def _reference_soft(state, triangles, rays: int, spread_deg: float):
    """Fraction of the spiral's directions reaching the light from each face pixel (trimesh)."""
    face, occluded, n_dot_l, _ = reference_occlusion(
        state, triangles, shadow_directions(state.params.directional_light.direction, rays,
                                            spread_deg))
    return face, 1.0 - occluded.mean(axis=0), n_dot_l


@pytest.mark.parametrize("yaw,azimuth,elevation", [(-10, -45, 30), (20, 55, 15)])
def test_soft_shadows_match_the_trimesh_average_over_the_light_disc(yaw, azimuth, elevation):
    """The soft visibility is the fraction of the disc's rays that reach the light.

    Agreement: on at least 99 % of face pixels the renderer's fraction equals the
    reference's; the rest are grazing (the two offset their rays off the surface
    differently), within the light's radius of ``n . l = 0``.
    Not vacuous: at least 1 % of face pixels are on a soft edge (0 < v < 1),
    and the hard render (1 ray) has no fractional pixel.
    """
    model = nosed_model()
    params = lit_scene(yaw, azimuth, elevation)
    state = Renderer(model, shadows=True, shadow_rays=RAYS,
                     shadow_spread_deg=SPREAD_DEG).init_state(params)
    visibility = state.full(state.shadow[1], fill=1.0)
    face, reference, n_dot_l = _reference_soft(state, model.triangles, RAYS, SPREAD_DEG)
    ours = visibility[face]
    equal = np.isclose(ours, reference, atol=1e-6)
    assert equal.mean() >= 0.99, equal.mean()
    grazing = math.sin(math.radians(SPREAD_DEG)) + 0.05
    assert np.all(np.abs(n_dot_l[~equal]) < grazing), n_dot_l[~equal]
    edge = (ours > 0.0) & (ours < 1.0)
    assert edge.mean() >= 0.01, edge.mean()

    hard = Renderer(model, shadows=True).init_state(params)
    assert set(np.unique(hard.shadow[1])) <= {0.0, 1.0}
    # the hard shadow's edge lies inside the soft band: where the hard render is lit and
    # the soft one fully shadowed (or the reverse) is rare
    hard_vis = hard.full(hard.shadow[1], fill=1.0)[face]
    assert np.mean(np.abs(hard_vis - ours) == 1.0) < 0.005


def test_soft_shadow_rays_are_counted_and_a_light_move_casts_only_them():
    """K rays per face pixel at the start and on a light-direction step; no primary ray."""
    model = nosed_model()
    renderer = Renderer(model, shadows=True, shadow_rays=RAYS, shadow_spread_deg=SPREAD_DEG)
    params = lit_scene(20, 55, 15)
    state = renderer.init_state(params)
    n_face = int(np.count_nonzero(state.hits.prim_id >= 0))
    assert renderer.ray_counts["shadow"] == RAYS * n_face
    before = dict(renderer.ray_counts)
    cand = renderer.update(state, params._replace(directional_light=side_light(-50, 25)),
                           Block.DIRECTIONAL)
    assert _delta(renderer, before) == {"primary": 0, "shadow": RAYS * n_face}
    assert cand.hits is state.hits


def test_bad_shadow_settings_are_refused():
    """A ray count below one or a spread outside [0, 45) degrees is a clear error."""
    model = nosed_model()
    with pytest.raises(InputError, match="shadow_rays"):
        Renderer(model, shadows=True, shadow_rays=0)
    with pytest.raises(InputError, match="shadow_rays"):
        FitConfig(shadow_rays=0)
    with pytest.raises(InputError, match="shadow_spread_deg"):
        FitConfig(shadow_spread_deg=math.inf)
