"""JAX shading: analytic cases, NumPy references, the naive reference, effect specialisation.

The split shader (per-pixel attributes, then shading without gathers):
test_pixel_shading.py. Scenes and jaxpr helpers: shading_scenes.py.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from shading_scenes import (
    COLOR, EFFECT_SETS, N_PIX, ROT, Scene, jaxpr_primitives, rgb_of, scene_params, used_inputs,
)

from albedo_model import sh
from albedo_model.params import ColorTransform, DirectionalLight, SHLight, default_square
from albedo_model.shading.image_formation import (
    Effects, build_shader, effects_for, encode_gamma, shade, shader_function, shading_params,
    to_hwc,
)
from albedo_model.shading.naive import shade_naive


def test_ambient_white_reproduces_interpolated_albedo():
    s = Scene(1)
    sp = shading_params(scene_params(SHLight.ambient_white()), ROT)
    out = shade(Effects(), *s.args(), sp)
    hit = s.prim_id >= 0
    np.testing.assert_array_equal(np.asarray(out.mask), hit)
    np.testing.assert_allclose(rgb_of(out)[hit], s.interp(s.diffuse)[hit], atol=1e-6)


def test_frontal_light_uses_rotated_renormalised_normals():
    s = Scene(2)
    white = np.ones_like(s.diffuse)
    sp = shading_params(scene_params(SHLight.frontal()), ROT)
    args = s.args()
    args[2] = jnp.asarray(white)
    out = rgb_of(shade(Effects(clamp=False), *args, sp))
    n = s.interp(s.normals) @ ROT.T
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    hit = s.prim_id >= 0
    np.testing.assert_allclose(out[hit], (0.8 + 0.2 * n[hit, 2])[:, None].repeat(3, 1), atol=2e-6)


def flat_hits(normals: np.ndarray):
    """One degenerate 'triangle' per pixel whose three corners share the pixel's normal."""
    p = len(normals)
    tri = np.arange(p)[:, None].repeat(3, 1).astype(np.int32)
    return tri, normals.astype(np.float32), np.arange(p, dtype=np.int32), np.full(
        (p, 2), 1 / 3, np.float32)


def fibonacci(n: int) -> np.ndarray:
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    phi = np.pi * (1 + 5**0.5) * i
    r = np.sqrt(1 - z * z)
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


def test_directional_lobe_in_sh_matches_clamped_cosine_within_order2_error():
    normals = fibonacci(N_PIX)
    ldir = np.array([0.3, 0.5, 0.8]) / np.linalg.norm([0.3, 0.5, 0.8])
    intensity = np.array([0.9, 0.6, 0.3])
    tri, nrm, pid, bary = flat_hits(normals)
    light = SHLight(sh.sh_from_directional(ldir, intensity))
    sp = shading_params(scene_params(light), np.eye(3))
    albedo = jnp.ones((N_PIX, 3), jnp.float32)
    out = rgb_of(shade(Effects(clamp=False), tri, nrm, albedo, None, pid, bary, None, sp))
    cos = normals @ ldir
    e2 = 0.25 + 0.5 * cos + 5 / 32 * (3 * cos**2 - 1)
    np.testing.assert_allclose(out, np.outer(e2, intensity), atol=2e-6)
    err = np.abs(out - np.outer(np.maximum(cos, 0), intensity)) / intensity
    assert err.max() <= 3 / 32 + 1e-5


def specular_setup(view_angles: np.ndarray, light: SHLight, exponent: float, s_alb: float):
    """Pixels on a surface with normal +z seen along directions tilted by ``view_angles`` in x."""
    p = len(view_angles)
    tri, nrm, pid, bary = flat_hits(np.tile([0.0, 0.0, 1.0], (p, 1)))
    v = np.column_stack([np.sin(view_angles), np.zeros(p), np.cos(view_angles)])
    ray_dirs = (-v * 3.0).astype(np.float32)  # length is irrelevant
    sp = shading_params(scene_params(light, exponent=exponent), np.eye(3))
    zeros = jnp.zeros((p, 3), jnp.float32)
    spec = jnp.full((p, 3), s_alb, jnp.float32)
    return (tri, nrm, zeros, spec, pid, bary, ray_dirs, sp), v


@pytest.mark.parametrize("exponent", [10.0, 20.0])
def test_specular_lobe_under_isotropic_light_is_cos_power(exponent):
    angles = np.linspace(0.0, 1.4, 16)
    args, _ = specular_setup(angles, SHLight.ambient_white(), exponent, 0.7)
    out = rgb_of(shade(Effects(specular=True, clamp=False), *args))
    np.testing.assert_allclose(out, (0.7 * np.cos(angles) ** exponent)[:, None].repeat(3, 1),
                               atol=1e-6)


def test_specular_uses_albedomm_reflection_not_mirror():
    angles = np.linspace(0.1, 1.2, 12)
    light = SHLight(sh.sh_from_ambient_diffuse([1.0] * 3, 1.0, (1.0, 0.0, 0.0)))  # E(r) = 1 + r_x
    args, v = specular_setup(angles, light, 2.0, 0.5)
    out = rgb_of(shade(Effects(specular=True, clamp=False), *args))[:, 0]
    n = np.array([0.0, 0.0, 1.0])
    vn = v @ n
    r = 2 * n - vn[:, None] * v
    r /= np.linalg.norm(r, axis=1, keepdims=True)
    expected = 0.5 * vn**2 * (1 + r[:, 0])
    np.testing.assert_allclose(out, expected, atol=1e-6)
    mirror = 2 * vn[:, None] * n - v
    assert np.abs(0.5 * vn**2 * (1 + mirror[:, 0]) - expected).max() > 0.05


def test_specular_matches_float64_reference_on_random_scene():
    s = Scene(4)
    light = SHLight(np.random.default_rng(5).normal(0, 0.3, (9, 3)) + SHLight.frontal().coefficients)
    sp = shading_params(scene_params(light, exponent=10.0), ROT)
    out = rgb_of(shade(Effects(specular=True, clamp=False), *s.args(), sp))
    n = s.interp(s.normals) @ ROT.T
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    v = -s.ray_dirs / np.linalg.norm(s.ray_dirs, axis=1, keepdims=True)
    vn = (v * n).sum(1)
    r = 2 * n - vn[:, None] * v
    r /= np.linalg.norm(r, axis=1, keepdims=True)
    ref = (s.interp(s.diffuse) * sh.sh_irradiance(light.coefficients, n)
           + (np.maximum(vn, 0) ** 10)[:, None] * s.interp(s.specular)
           * sh.sh_irradiance(light.coefficients, r))
    hit = s.prim_id >= 0
    np.testing.assert_allclose(out[hit], ref[hit], atol=1e-5)


def uniform_albedo_args(diffuse, specular):
    p = 16
    tri, nrm, pid, bary = flat_hits(fibonacci(p))
    d = jnp.asarray(np.tile(diffuse, (p, 1)), jnp.float32)
    s = jnp.asarray(np.tile(specular, (p, 1)), jnp.float32)
    return tri, nrm, d, s, pid, bary, np.tile([0.0, 0.0, -1.0], (p, 1)).astype(np.float32)


def test_color_transform_hand_computed():
    # Y = .3*.2 + .59*.4 + .11*.6 = .362; c' = gain (.7 c + .3 Y) + offset.
    sp = shading_params(scene_params(SHLight.ambient_white(), color=COLOR), np.eye(3))
    args = uniform_albedo_args([0.2, 0.4, 0.6], [0.0, 0.0, 0.0])
    out = rgb_of(shade(Effects(color_transform=True), *args, sp))
    np.testing.assert_allclose(out, np.tile([0.28346, 0.36974, 0.66432], (16, 1)), atol=1e-6)


def test_offset_counts_twice_with_specular():
    """AlbedoMM transforms D and S separately: with zero specular albedo, S' = offset."""
    sp = shading_params(scene_params(SHLight.ambient_white(), color=COLOR), np.eye(3))
    args = uniform_albedo_args([0.2, 0.4, 0.6], [0.0, 0.0, 0.0])
    out = rgb_of(shade(Effects(specular=True, color_transform=True), *args, sp))
    np.testing.assert_allclose(out, np.tile([0.29346, 0.38974, 0.69432], (16, 1)), atol=1e-6)


def test_directional_light_and_shadow_hand_computed():
    """n = l = v = +z: image = rho (amb + diff vis) + spec vis; SH off."""
    dl = DirectionalLight((0.1, 0.2, 0.3), (0.5, 0.4, 0.3), (0.0, 0.0, 2.0), (0.05, 0.1, 0.0), 10.)
    sp = shading_params(scene_params(SHLight.empty(), directional=dl), np.eye(3))
    tri, nrm, pid, bary = flat_hits(np.tile([0.0, 0.0, 1.0], (4, 1)))
    rho = jnp.full((4, 3), 0.5, jnp.float32)
    dirs = np.tile([0.0, 0.0, -1.0], (4, 1)).astype(np.float32)
    vis = jnp.asarray([0.0, 1.0, 0.5, 1.0], jnp.float32)
    eff = Effects(sh_coefficients=0, directional=True, shadows=True)
    out = rgb_of(shade(eff, tri, nrm, rho, None, pid, bary, dirs, sp, vis))
    amb, dif, spe = (np.array(x) for x in (dl.ambient, dl.diffuse, dl.specular))
    expected = np.array([0.5 * (amb + dif * w) + spe * w for w in (0.0, 1.0, 0.5, 1.0)])
    np.testing.assert_allclose(out, expected, atol=1e-6)


def test_encode_gamma_values_nan_free_and_gradient_finite():
    x = jnp.asarray([-1.0, 0.0, 1e-12, 0.25, 1.0], jnp.float32)
    y = np.asarray(encode_gamma(x))
    np.testing.assert_allclose(y, [0, 0, 0, 0.25 ** (1 / 2.2), 1.0], rtol=1e-6)
    grads = np.asarray(jax.jit(jax.vmap(jax.grad(encode_gamma)))(x))
    assert np.all(np.isfinite(grads))
    assert grads[0] == 0 and grads[1] == 0
    assert grads[3] == pytest.approx(0.25 ** (1 / 2.2 - 1) / 2.2, rel=1e-5)


def test_shading_with_gamma_is_nan_free_and_differentiable_at_black():
    s = Scene(6)
    args = s.args()
    args[2] = jnp.zeros_like(args[2])  # black albedo: everything hits gamma(0)
    sp = shading_params(scene_params(exponent=20.0), ROT)
    eff = Effects(specular=True, directional=False, gamma=True)
    fn = shader_function(eff)

    def total(sh_coeffs):
        out = fn(*args, sp._replace(sh=sh_coeffs), None)
        return sum(jnp.sum(c) for c in out.rgb)

    value, grad = jax.jit(jax.value_and_grad(total))(sp.sh)
    assert np.isfinite(float(value))
    assert np.all(np.isfinite(np.asarray(grad)))


def test_background_colour_on_misses():
    s = Scene(7)
    sp = shading_params(scene_params(), ROT, background=(0.1, 0.2, 0.3))
    out = shade(Effects(gamma=True), *s.args(), sp)
    miss = s.prim_id < 0
    np.testing.assert_array_equal(rgb_of(out)[miss], np.tile([0.1, 0.2, 0.3], (miss.sum(), 1))
                                  .astype(np.float32))
    img = to_hwc(out.rgb, 24, 24)
    assert img.shape == (24, 24, 3)
    np.testing.assert_array_equal(img[0, 1], rgb_of(out)[1])


@pytest.mark.parametrize("effects", EFFECT_SETS, ids=str)
def test_specialised_equals_naive(effects):
    s = Scene(8)
    light = SHLight(np.random.default_rng(9).normal(0, 0.25, (9, 3)) + SHLight.frontal().coefficients)
    dl = DirectionalLight((0.1, 0.1, 0.2), (0.5, 0.4, 0.3), (0.3, 0.2, 1.0), (0.2, 0.1, 0.1), 12.)
    sp = shading_params(scene_params(light, dl, COLOR, exponent=10.0), ROT, background=(0, 0.5, 1))
    shadow = jnp.asarray(s.shadow)
    fast = shade(effects, *s.args(), sp, shadow)
    slow = shade_naive(effects, *s.args(), sp, shadow)
    np.testing.assert_array_equal(np.asarray(fast.mask), np.asarray(slow.mask))
    np.testing.assert_allclose(rgb_of(fast), rgb_of(slow), atol=1e-5)


# Flattened argument positions: 0 triangles, 1 normals, 2 diffuse, 3 specular, 4 prim_id,
# 5 bary, 6 ray_dirs, 7.. the 12 ShadingParams fields, 19 shadow.
_PARAM = {name: 7 + i for i, name in enumerate(
    ["rotation", "sh", "specular_exponent", "light_direction", "light_ambient", "light_diffuse",
     "light_specular", "light_shininess", "color_gain", "color_contrast", "color_offset",
     "background"])}


def _trace(effects):
    s = Scene(10)
    sp = shading_params(scene_params(), ROT)
    closed = jax.make_jaxpr(shader_function(effects))(*s.args(), sp, jnp.asarray(s.shadow))
    return jaxpr_primitives(closed.jaxpr), used_inputs(closed, 20)


def test_switched_off_effects_are_not_traced():
    prims_off, used_off = _trace(Effects())
    prims_spec, used_spec = _trace(Effects(specular=True))
    prims_all, used_all = _trace(Effects(specular=True, directional=True, shadows=True,
                                         color_transform=True, gamma=True))
    # No transcendental work without specular / gamma; the specular lobe adds exp and log.
    assert prims_off.count("exp") == 0 and prims_off.count("log") == 0
    assert prims_spec.count("exp") >= 1 and prims_spec.count("log") >= 1
    assert len(prims_spec) > len(prims_off)
    # Inputs of switched-off effects are never read.
    for i in (3, 6, 19, _PARAM["specular_exponent"], _PARAM["light_direction"],
              _PARAM["light_shininess"], _PARAM["color_gain"], _PARAM["color_offset"]):
        assert i not in used_off
    assert {3, 6, _PARAM["specular_exponent"]} <= used_spec
    assert _PARAM["light_direction"] not in used_spec and 19 not in used_spec
    assert {3, 6, 19, _PARAM["light_shininess"], _PARAM["color_gain"],
            _PARAM["color_contrast"], _PARAM["color_offset"]} <= used_all
    assert prims_all.count("log") > prims_spec.count("log")  # gamma and Blinn-Phong


def test_effects_for_scene_switches():
    p = default_square()
    assert effects_for(p, has_specular=True) == Effects(9, specular=True)
    assert effects_for(p, has_specular=False) == Effects(9)
    assert effects_for(p, True, specular=False).specular is False
    empty = p._replace(environment_map=SHLight.empty())
    assert effects_for(empty, True) == Effects(sh_coefficients=0)
    dl = p._replace(directional_light=DirectionalLight(diffuse=(1.0, 1.0, 1.0)))
    assert effects_for(dl, False, shadows=True) == Effects(9, directional=True, shadows=True)
    assert effects_for(p, False, shadows=True).shadows is False
    ct = p._replace(color_transform=ColorTransform(offset=(0.0, 0.1, 0.0)))
    assert effects_for(ct, False, gamma=True) == Effects(9, color_transform=True, gamma=True)
    with pytest.raises(ValueError):
        shading_params(p._replace(environment_map=SHLight(np.ones((9, 1)))), np.eye(3))
    four = p._replace(environment_map=SHLight(np.ones((4, 3))))
    assert effects_for(four, True).sh_coefficients == 4
    sp = shading_params(four, np.eye(3))
    np.testing.assert_array_equal(np.asarray(sp.sh)[4:], 0.0)


def test_shader_cache_and_validation():
    assert build_shader(Effects(specular=True)) is build_shader(Effects(specular=True))
    with pytest.raises(ValueError):
        shader_function(Effects(shadows=True))
    with pytest.raises(ValueError):
        shader_function(Effects(sh_coefficients=0, specular=True))
    with pytest.raises(ValueError):
        shader_function(Effects(sh_coefficients=10))
