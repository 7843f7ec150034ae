"""End-to-end rendering: against a z-buffer, on the scalismo head, through ``mcmcfit render``.

Also specular and shadows, and view directions against the naive shader.
Cached block updates, fused likelihoods and pixel sets: test_renderer_steps.py;
model and scenes: renderer_scenes.py.
"""

from __future__ import annotations

import numpy as np
import pytest
from renderer_scenes import bumpy_model, scene, zbuffer_image

from albedo_model.model import vertex_normals
from albedo_model.params import MoMoCoefficients, SHLight
from albedo_model.render.renderer import Renderer


@pytest.mark.parametrize("yaw,pitch", [(0.0, 0.0), (0.5, -0.3), (1.3, 0.2)])
def test_renderer_matches_zbuffer_reference(yaw, pitch):
    model = bumpy_model()
    sh = SHLight(np.array([[0.9, 0.8, 0.7], [0.1, 0.0, -0.1], [0.3, 0.3, 0.2], [-0.2, 0.1, 0.0],
                           [0.05, 0, 0], [0, 0.05, 0], [0.02, 0.02, 0.02], [0, 0, 0.03], [0.01, 0, 0]]))
    params = scene(yaw=yaw, pitch=pitch, sh=sh)
    out = Renderer(model, specular=False).render(params)
    ref, ref_mask = zbuffer_image(model, params, sh.coefficients)
    agree = (out.mask == ref_mask).mean()
    assert agree >= 0.995, agree
    both = out.mask & ref_mask
    assert both.sum() > 500
    assert np.abs(out.image[both] - ref[both]).max() <= 1e-4


def test_ambient_white_reproduces_albedo():
    model = bumpy_model()
    params = scene()
    out = Renderer(model, specular=False).render(params)
    ref, mask = zbuffer_image(model, params, SHLight.ambient_white().coefficients)
    both = out.mask & mask
    np.testing.assert_allclose(out.image[both], ref[both], atol=1e-4)


def test_specular_and_directional_light_with_shadows_are_finite():
    from albedo_model.params import DirectionalLight
    model = bumpy_model()
    params = scene(sh=SHLight.frontal())._replace(
        directional_light=DirectionalLight((0.1,) * 3, (0.8,) * 3, (1.0, 0.3, 0.5), (0.2,) * 3, 20.0),
        specular_exponent=20.0,
    )
    r = Renderer(model, shadows=True, gamma=True)
    assert r.effects(params).shadows and r.effects(params).specular
    out = r.render(params)
    assert np.isfinite(out.image).all() and out.image.max() <= 1.0
    lit = Renderer(model, shadows=False, gamma=True).render(params)
    # shadows only darken
    assert np.all(out.image <= lit.image + 1e-6)
    assert (out.image < lit.image - 1e-3).any()


def test_scalismo_head_landmarks(shared_data, tmp_path):
    """random-l4 mean with the pose, camera and light of AlbedoMM's lminit at 250x250."""
    from albedo_model.camera import project
    from albedo_model.io.image_io import write_png
    from albedo_model.io.model_files import load_model
    from albedo_model.io.rps import read_rps

    model = load_model(shared_data / "scalismo" / "random-l4.h5")
    p = read_rps(shared_data / "scalismo" / "albedomm-fitter-lminit.rps")
    p = p._replace(momo=MoMoCoefficients.zeros())
    renderer = Renderer(model)
    out = renderer.render(p)
    names, px, vis = renderer.landmarks(out.state)
    write_png(tmp_path / "head.png", out.image, alpha=out.mask)
    lm = dict(zip(names, px))
    # the formula, evaluated independently
    v = model.shape.mean.reshape(-1, 3)[model.landmark_vertices["center.nose.tip"]]
    expected, _ = project(v[None], p.pose, p.view, p.camera, p.image_size)
    np.testing.assert_allclose(lm["center.nose.tip"], expected[0], atol=1e-9)
    # visible landmarks lie on the rendered face (within a pixel: ear rims are silhouette)
    for name, (x, y), visible in zip(names, px, vis):
        if visible:
            j, i = int(round(y)), int(round(x))
            assert out.mask[j - 1:j + 2, i - 1:i + 2].any(), name
    assert lm["left.eye.corner_outer"][0] > lm["right.eye.corner_outer"][0]  # subject's left = image right
    assert lm["left.lips.corner"][0] > lm["right.lips.corner"][0]
    order = ["right.eyebrow.bend.lower", "right.eye.corner_outer", "center.nose.tip",
             "center.lips.upper.outer", "center.lips.lower.outer", "center.chin.tip"]
    ys = [lm[n][1] for n in order]
    assert ys == sorted(ys), dict(zip(order, ys))
    visible = dict(zip(names, vis))
    assert all(visible[n] for n in order)
    assert 0.1 < out.mask.mean() < 0.6


def test_render_cli_png_rgba_and_linear(shared_data, tmp_path):
    import imageio.v3 as iio

    from mcmcfit.cli import main
    model = shared_data / "scalismo" / "random-l4.h5"
    rps = shared_data / "scalismo" / "albedomm-fitter-lminit.rps"
    # lminit holds 50 zero coefficients; this model has rank 19 and zeros beyond are an error
    from albedo_model.io.rps import read_rps, write_rps
    p = read_rps(rps)
    write_rps(tmp_path / "p.rps", p._replace(momo=MoMoCoefficients.zeros(19, 19)))
    assert main(["render", str(model), str(tmp_path / "p.rps"), "-o", str(tmp_path / "a.png")]) == 0
    a = iio.imread(tmp_path / "a.png")
    assert a.shape == (250, 250, 4) and a.dtype == np.uint8
    assert set(np.unique(a[..., 3])) == {0, 255}
    assert main(["render", str(model), str(tmp_path / "p.rps"), "-o", str(tmp_path / "b.png"),
                 "--linear", "--size", "100x80"]) == 0
    import png
    w, h, rows, info = png.Reader(filename=str(tmp_path / "b.png")).read()
    assert (w, h, info["bitdepth"], info["planes"]) == (100, 80, 16, 4)
    b = np.vstack([np.asarray(r, np.uint16) for r in rows]).reshape(80, 100, 4)
    assert b[..., 3].max() == 65535 and b[..., :3].max() > 0


def test_render_cli_bad_input(shared_data, tmp_path, capsys):
    from mcmcfit.cli import main
    model = shared_data / "scalismo" / "random-l4.h5"
    bad = tmp_path / "bad.rps"
    bad.write_text('{"version": "V9.0"}')
    out = tmp_path / "x.png"
    assert main(["render", str(model), str(bad), "-o", str(out)]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bad.rps" in err[0]
    assert not out.exists()
    # too many coefficients for the model
    rps = shared_data / "scalismo" / "albedomm-fit-best.rps"
    assert main(["render", str(model), str(rps), "-o", str(out)]) != 0
    assert "rank 19" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize("ortho", [False, True])
def test_view_directions_of_specular_shading_match_the_camera_rays(ortho):
    """The renderer derives each pixel's view direction on the device from the camera; the
    naive shader is given the world-frame camera rays instead: same image (off-centre
    principal point, a turned camera, Blinn-Phong and AlbedoMM specular on)."""
    from albedo_model.camera import _eye_rays, euler_rotation, eye_from_world
    from albedo_model.params import DirectionalLight, View
    from albedo_model.shading.image_formation import shading_params
    from albedo_model.shading.naive import shade_naive

    model = bumpy_model()
    params = scene(sh=SHLight.frontal(), pp=(0.2, -0.15))._replace(
        view=View((5.0, -3.0, 2.0), 0.05, -0.08, 0.04),
        directional_light=DirectionalLight((0.1,) * 3, (0.6,) * 3, (0.5, 0.4, 1.0), (0.3,) * 3,
                                           15.0),
        specular_exponent=12.0,
    )
    if ortho:
        params = params._replace(camera=params.camera._replace(orthographic=True, near=600.0))
    renderer = Renderer(model, directional_specular_map=False)
    out = renderer.render(params)
    st = out.state
    eff = renderer.effects(params)
    assert eff.specular and eff.directional and st.hits.mask.sum() > 100
    _, eye_dirs = _eye_rays(params.camera, params.image_size)
    r_view, _ = eye_from_world(params.view)
    ray_dirs = (eye_dirs[:, :3].astype(np.float64) @ r_view).astype(np.float32)
    verts = st.shape.reshape(-1, 3)
    rotation = euler_rotation(params.pose.roll, params.pose.yaw, params.pose.pitch)
    ref = shade_naive(eff, model.triangles.astype(np.int32),
                      vertex_normals(verts, model.triangles).astype(np.float32),
                      st.diffuse.reshape(-1, 3), st.specular.reshape(-1, 3), st.hits.prim_id,
                      st.hits.bary, ray_dirs, shading_params(params, rotation))
    want = np.stack([np.asarray(c) for c in ref.rgb], -1).reshape(out.image.shape)
    np.testing.assert_allclose(out.image[out.mask], want[out.mask], atol=2e-5)
