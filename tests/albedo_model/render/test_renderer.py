"""End-to-end rendering: the cached renderer against a brute-force z-buffer,
against a full re-render, on the scalismo head, and through ``mcmcfit render``."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from zbuffer_reference import render_zbuffer

from albedo_model.model import MorphableModel, vertex_normals
from albedo_model.params import (
    Block, Camera, ColorTransform, ImageSize, MoMoCoefficients, Pose, SHLight, default_square,
)
from albedo_model.pca import PCAPart
from albedo_model.render.renderer import Renderer
from albedo_model.sh import sh_irradiance


def bumpy_model(seed=0, k=4):
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=60.0)
    v = np.asarray(mesh.vertices)
    v = v * (1.0 + 0.08 * np.sin(3 * v[:, :1] / 60.0) * np.cos(2 * v[:, 1:2] / 60.0))
    rng = np.random.default_rng(seed)
    n3 = 3 * len(v)

    def part(mean, scale):
        q, _ = np.linalg.qr(rng.standard_normal((n3, k)))
        return PCAPart(mean, q, np.full(k, scale))

    colour = 0.5 + 0.3 * np.sin(v / 17.0)
    return MorphableModel(v, np.asarray(mesh.faces), part(v.ravel(), 400.0),
                          part(colour.ravel(), 0.5), specular=part(np.full(n3, 0.3), 0.2))


def scene(size=(64, 48), yaw=0.3, pitch=-0.2, sh=None, pp=(0.05, -0.1)):
    p = default_square()
    sh = SHLight.ambient_white() if sh is None else sh
    return p._replace(
        pose=Pose(1.0, (4.0, -3.0, -700.0), 0.1, yaw, pitch),
        camera=Camera(focal_length=7.5, sensor_size=(2.0, 2.0 * size[1] / size[0]),
                      principal_point=pp),
        image_size=ImageSize(*size), environment_map=sh,
        momo=MoMoCoefficients(np.array([0.3, -0.2]), np.array([0.5, 0.1, -0.4]), np.zeros(0)),
    )


def zbuffer_image(model, params, sh_coeffs):
    """Independent reference: numpy z-buffer + barycentric interpolation + numpy SH."""
    verts = model.shape_instance(params.momo.shape)
    albedo = model.diffuse_instance(params.momo.albedo)
    normals = vertex_normals(verts, model.triangles)
    prim, bary, _ = render_zbuffer(verts, model.triangles, params.pose, params.view, params.camera,
                                params.image_size)
    hit = prim >= 0
    tri = model.triangles[np.maximum(prim, 0)]
    w = np.stack([1 - bary[..., 0] - bary[..., 1], bary[..., 0], bary[..., 1]], -1)
    interp = lambda a: np.einsum("hwk,hwkc->hwc", w, a[tri])  # noqa: E731
    from albedo_model.camera import euler_rotation
    r = euler_rotation(params.pose.roll, params.pose.yaw, params.pose.pitch)
    n = interp(normals) @ r.T
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    img = interp(albedo) * sh_irradiance(sh_coeffs, n)
    return np.where(hit[..., None], np.clip(img, 0, 1), 0.0), hit


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


def moves(params, rng):
    """One changed parameter set per block, as a proposal would make."""
    m = params.momo
    yield Block.POSE, params._replace(pose=params.pose._replace(yaw=params.pose.yaw + 0.2))
    yield Block.CAMERA, params._replace(camera=params.camera._replace(focal_length=8.0))
    yield Block.SHAPE, params._replace(momo=m._replace(shape=m.shape + rng.normal(0, 1, 2)))
    yield Block.ALBEDO, params._replace(momo=m._replace(albedo=m.albedo + rng.normal(0, 1, 3)))
    sh = params.environment_map.coefficients * 0.7
    yield Block.LIGHT, params._replace(environment_map=SHLight(sh))
    yield Block.COLOR_TRANSFORM, params._replace(color_transform=ColorTransform((1.1, 0.9, 1.0), 0.8, (0.01, 0, 0)))


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
    """A LIGHT step adding a directional light needs view directions the cache lacked."""
    from albedo_model.params import DirectionalLight
    model = bumpy_model()
    renderer = Renderer(model, specular=False)
    state = renderer.init_state(scene(sh=SHLight.frontal()))
    assert state.pixel_geometry.view is None
    lit = state.params._replace(directional_light=DirectionalLight(
        (0.1,) * 3, (0.6,) * 3, (0.3, 0.4, 1.0), (0.3,) * 3, 15.0))
    cand = renderer.update(state, lit, Block.LIGHT)
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
