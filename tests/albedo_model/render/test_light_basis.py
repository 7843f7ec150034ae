"""The light transport's SH basis: it reproduces the renderer's transport for any light."""

from __future__ import annotations

import numpy as np
import pytest
from renderer_scenes import bumpy_model, scene

from albedo_model.params import Block, SHLight
from albedo_model.render.light_basis import light_basis
from albedo_model.render.renderer import Renderer


@pytest.mark.parametrize("specular", [False, True])
def test_basis_times_a_light_is_the_renderers_transport(specular):
    model = bumpy_model()
    renderer = Renderer(model, specular=specular)
    rng = np.random.default_rng(1)
    params = scene()
    state = renderer.init_state(params)
    b, s = light_basis(state)
    assert (s is not None) == specular
    for _ in range(3):
        light = SHLight.frontal().coefficients + rng.normal(0, 0.2, (9, 3))
        moved = renderer.update(state, params._replace(environment_map=SHLight(light)),
                                Block.LIGHT)
        transport = moved.pixel_light.value
        for c in range(3):
            ref = np.asarray(transport.diffuse[c])
            assert np.allclose(b @ light[:, c], ref, atol=2e-5 * max(1.0, np.abs(ref).max()))
            if specular:
                ref_s = np.asarray(transport.specular[c])
                assert np.allclose(s @ light[:, c], ref_s,
                                   atol=2e-5 * max(1.0, np.abs(ref_s).max()))
