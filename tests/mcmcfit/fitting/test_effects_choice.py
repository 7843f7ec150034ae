"""The evidence for a directional light: on where a photograph has one, off where SH light explains it.

Ground truth: renders of a small face model at known geometry and albedo, lit
by a side light (Lambert + Blinn-Phong, cast shadows) over a weak SH light, or
by an SH light alone, with pixel noise. The evidence fits the light at the
true geometry and albedo (which it re-solves with the light), so it must find
the side light's direction.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from face_factory import scene, small_face_model

from albedo_model.params import DirectionalLight, MoMoCoefficients, SHLight
from albedo_model.render.renderer import Renderer
from mcmcfit.fitting.effects_choice import (REFINED, SCREEN_RATIO, directional_evidence,
                                             with_directional)

SIZE = 96
SIGMA = 0.01


@pytest.fixture(scope="module")
def model():
    return small_face_model(subdivisions=5)


def _photo(model, light: DirectionalLight, seed: int):
    rng = np.random.default_rng(seed)
    p = scene(SIZE, SIZE, yaw=0.2, coefficients=MoMoCoefficients(
        rng.normal(size=4), rng.normal(size=3), rng.normal(size=2)))
    p = p._replace(environment_map=SHLight.frontal(0.35, 0.1), directional_light=light)
    r = Renderer(model, shadows=True, directional_specular_map=True, threads=1)
    image = r.render(p).image + rng.normal(0.0, SIGMA, (SIZE, SIZE, 3))
    return p, image


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_side_light_is_found_and_switched_on(model, seed):
    """A side light (60 deg azimuth, 20 deg up): the evidence is far above its threshold, in its direction."""
    light = DirectionalLight.from_angles(math.radians(60 if seed % 2 else -60), math.radians(20),
                                         (0.8, 0.75, 0.7), shininess=20.0)
    truth, image = _photo(model, light, seed)
    r = Renderer(model, shadows=True, directional_specular_map=True, threads=1)
    ev = directional_evidence(r, image, truth, np.ones(SIZE * SIZE, bool), SIGMA, 1.0)
    assert ev["on"] and ev["gain"] > 3 * ev["threshold"]
    assert abs(ev["azimuth_deg"] - math.degrees(light.angles()[0])) <= 15.0
    assert abs(ev["elevation_deg"] - 20.0) <= 15.0
    # deciding casts the cast shadows of a few candidate directions, nothing more
    assert 0 < r.ray_counts["shadow"] <= REFINED * SIZE * SIZE
    assert ev["first_pass_ratio"] >= SCREEN_RATIO
    start = with_directional(truth, ev).directional_light
    assert start.enabled and np.all(np.asarray(start.diffuse) > 0.3)


@pytest.mark.parametrize("seed", [3, 4])
def test_sh_light_alone_stays_sh(model, seed):
    """A photograph lit by the SH light alone: the directional light gains less than its threshold."""
    truth, image = _photo(model, DirectionalLight(), seed)
    truth = truth._replace(environment_map=SHLight.frontal(0.7, 0.4))
    r = Renderer(model, shadows=True, directional_specular_map=True, threads=1)
    image = r.render(truth).image + np.random.default_rng(seed).normal(0, SIGMA, image.shape)
    ev = directional_evidence(r, image, truth, np.ones(SIZE * SIZE, bool), SIGMA, 1.0)
    assert not ev["on"], ev
    assert r.ray_counts["shadow"] <= REFINED * SIZE * SIZE
