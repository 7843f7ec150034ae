"""``mcmcfit render`` with a directional light: its cast shadows, as the fit renders them."""

from __future__ import annotations

import numpy as np
import pytest
from shadow_scenes import lit_scene, nosed_model

from albedo_model.io.image_io import read_image
from albedo_model.io.momo_h5 import write_model_h5
from albedo_model.io.rps import read_rps, write_rps
from albedo_model.render.renderer import Renderer
from mcmcfit.cli import main


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """The sphere-with-a-nose model and an .rps of it under a side light."""
    d = tmp_path_factory.mktemp("cli-render")
    params = lit_scene(20, 55, 15)
    write_model_h5(nosed_model(), d / "nosed.h5")
    write_rps(d / "lit.rps", params)
    return d, params


def _rgb(path):
    return read_image(path)[..., :3]


def test_render_casts_the_directional_lights_shadows(files, tmp_path, capsys):
    """The PNG equals the fit's renderer (shadows, highlight by the specular map) to 8 bits.

    ``--no-shadows`` lights the cast-shadow pixels instead: at least 1 % of the
    face gets brighter and none darker; ``--soft-shadows 8`` puts a band of
    in-between values along the shadow's edge.
    """
    d, _ = files
    params = read_rps(d / "lit.rps")  # the round trip keeps the directional light
    assert params.directional_light.enabled
    expected = Renderer(nosed_model(), gamma=True, shadows=True,
                        directional_specular_map=True).render(params)
    assert main(["render", str(d / "nosed.h5"), str(d / "lit.rps"), "-o",
                 str(tmp_path / "hard.png")]) == 0
    assert "cast shadows" in capsys.readouterr().out
    hard = _rgb(tmp_path / "hard.png")
    face = expected.mask
    assert np.max(np.abs(hard[face] - expected.image[face])) <= 1.0 / 255 + 1e-6

    assert main(["render", str(d / "nosed.h5"), str(d / "lit.rps"), "-o",
                 str(tmp_path / "lit.png"), "--no-shadows"]) == 0
    unshadowed = _rgb(tmp_path / "lit.png")
    gain = (unshadowed - hard).sum(axis=2)[face]
    assert np.mean(gain > 3.0 / 255) >= 0.01
    assert np.all(gain >= -3.0 / 255)

    assert main(["render", str(d / "nosed.h5"), str(d / "lit.rps"), "-o",
                 str(tmp_path / "soft.png"), "--soft-shadows", "8"]) == 0
    soft = _rgb(tmp_path / "soft.png")
    between = ((soft - hard).sum(axis=2)[face] > 3.0 / 255) & (
        (unshadowed - soft).sum(axis=2)[face] > 3.0 / 255)
    assert between.sum() >= 20


def test_render_refuses_a_bad_ray_count(files, tmp_path, capsys):
    d, _ = files
    out = tmp_path / "x.png"
    assert main(["render", str(d / "nosed.h5"), str(d / "lit.rps"), "-o", str(out),
                 "--soft-shadows", "0"]) == 2
    assert "--soft-shadows" in capsys.readouterr().err
    assert not out.exists()
