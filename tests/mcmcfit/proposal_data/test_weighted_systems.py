"""Fixed per-pixel weights of the conditionals' Gaussian systems (a robust foreground's).

Independent truths: a weight of 0 is the pixel left out (the same system as a
region without it), a constant weight c scales the normal equations by c.
"""

from __future__ import annotations

import numpy as np
from face_factory import scene, small_face_model, synthetic_target

from albedo_model.params import MoMoCoefficients
from albedo_model.render.renderer import Renderer
from mcmcfit.proposal_data.albedo import RenderAlbedoData
from mcmcfit.proposal_data.light_system import RenderLightSystem
from mcmcfit.targets.image import linearise
from proposals.albedo_solver import conditional_terms
from proposals.base import ProposalState

SIZE = 48


def _case():
    model = small_face_model(subdivisions=3)
    rng = np.random.default_rng(4)
    p = scene(SIZE, SIZE, yaw=0.2, coefficients=MoMoCoefficients(
        np.zeros(0), rng.normal(size=3), np.zeros(0)))
    image, _ = synthetic_target(model, p)
    target = np.clip(linearise(image) + rng.normal(0, 0.02, image.shape), 0, 1)
    renderer = Renderer(model, specular=False, threads=1)
    state = ProposalState(p, renderer.init_state(p))
    keep = rng.random(SIZE * SIZE) < 0.6
    return renderer, target, state, keep


def test_light_system_weights():
    _, target, state, keep = _case()
    full = RenderLightSystem(target)(state)
    dropped = RenderLightSystem(target, weights=keep.astype(float))(state)
    region = RenderLightSystem(target, region=keep)(state)
    np.testing.assert_allclose(dropped.gram, region.gram, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(dropped.rhs, region.rhs, rtol=1e-9, atol=1e-12)
    halved = RenderLightSystem(target, weights=np.full(SIZE * SIZE, 0.5))(state)
    np.testing.assert_allclose(halved.gram, 0.5 * full.gram, rtol=1e-9)
    np.testing.assert_allclose(halved.rhs, 0.5 * full.rhs, rtol=1e-9, atol=1e-12)
    assert not np.allclose(region.gram, full.gram)


def test_albedo_system_weights():
    renderer, target, state, keep = _case()

    def terms(**kw):
        data = RenderAlbedoData(renderer, target, n_points=10**6, **kw)
        return conditional_terms(data(state), 1.0, 0.05)

    full = terms()
    dropped = terms(weights=keep.astype(float))
    region = terms(region=keep)
    for a, b in zip(dropped, region):
        np.testing.assert_allclose(a, b, rtol=2e-4, atol=1e-3 * np.abs(b).max())
    halved = terms(weights=np.full(SIZE * SIZE, 0.5))
    for a, b in zip(halved, full):
        np.testing.assert_allclose(a, 0.5 * b, rtol=2e-4, atol=1e-3 * np.abs(b).max())
    assert not np.allclose(region[0], full[0])


def test_directional_strength_joins_the_light_system():
    """On a noiseless render the conditional mean recovers the SH light and the RGB strength.

    The sphere with a nose under a side light, cast shadows on, its highlight the
    colour of its diffuse term (the fit's light): a state with another SH light and
    strength (same direction, geometry, albedo) gives the exact ones back (tiny sigma,
    flat prior), and the light move then touches LIGHT | DIRECTIONAL_STRENGTH (not the
    direction the cast shadows depend on). Without
    ``directional`` the strength stays an offset: the system has only the SH rows.
    """
    from shadow_scenes import lit_scene, nosed_model

    from albedo_model.params import Block, DirectionalLight, SHLight
    from proposals.light_conditional import LightConditional

    model = nosed_model()
    truth = lit_scene(20, 55, 15)
    az, el = truth.directional_light.angles()
    truth = truth._replace(directional_light=DirectionalLight.from_angles(
        az, el, (0.6, 0.5, 0.4), shininess=20.0))
    renderer = Renderer(model, shadows=True, directional_specular_map=True, threads=1)
    target = np.asarray(renderer.render(truth).image, np.float64)
    k = truth.environment_map.coefficients.shape[0]
    other = truth._replace(
        environment_map=SHLight(truth.environment_map.coefficients * 0.8 + 0.02),
        directional_light=DirectionalLight.from_angles(az, el, (0.3, 0.35, 0.2),
                                                       shininess=20.0))
    state = ProposalState(other, renderer.init_state(other))
    system = RenderLightSystem(target, directional=True)(state)
    assert system.directional and system.gram.shape == (3 * (k + 1), 3 * (k + 1))
    assert not RenderLightSystem(target)(state).directional
    flat = np.full((k, 3), 1e6)
    prop = LightConditional(lambda s: system, np.zeros((k, 3)), flat, sigma=1e-4)
    move = prop(np.random.default_rng(0), state)
    assert move.touched == Block.LIGHT | Block.DIRECTIONAL_STRENGTH  # the shadows stay
    np.testing.assert_allclose(move.params.directional_light.diffuse, (0.6, 0.5, 0.4), atol=2e-3)
    np.testing.assert_allclose(move.params.directional_light.specular,
                               move.params.directional_light.diffuse)
    np.testing.assert_allclose(move.params.environment_map.coefficients,
                               truth.environment_map.coefficients, atol=5e-3)
    assert move.params.directional_light.direction == other.directional_light.direction
