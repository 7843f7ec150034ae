"""Small scenes shared by the tests of the Gaussian sampler's coordinates and moves."""

from __future__ import annotations

import numpy as np
from face_factory import scene, small_face_model
from mh_chain import base_state

from albedo_model.params import MoMoCoefficients, RenderParameter, SHLight
from proposals.laplace.image_scale import ImageScale


def small_template() -> RenderParameter:
    """Return a scene with 2 shape, 2 albedo and 1 expression coefficients and a 1-band light."""
    p = base_state()
    momo = MoMoCoefficients(np.array([0.1, -0.2]), np.array([0.3, 0.1]), np.array([0.05]), "")
    return p._replace(momo=momo, environment_map=SHLight(SHLight.frontal().coefficients[:1]),
                      specular_exponent=20.0)


def image_scale_case():
    """Return ``(model, params, anchor ids, ImageScale)``: a small face turned and shifted off-axis."""
    model = small_face_model(subdivisions=3)
    rng = np.random.default_rng(3)
    params = scene(64, 64, yaw=0.3, pitch=-0.1, roll=0.05, translation=(12.0, -8.0, -950.0),
                   coefficients=MoMoCoefficients(rng.normal(size=4), rng.normal(size=3),
                                                 rng.normal(0, 0.7, 2)))
    ids = np.arange(0, model.shape.dim // 3, 3)
    return model, params, ids, ImageScale.of_model(model, params, ids)
