"""The split shader: per-pixel attributes, then shading without gathers.

Interpolated attributes against NumPy, the pixel shader against the full one,
packed shading parameters, what the pixel shader traces, and light transport
times albedo. Scenes and jaxpr helpers: shading_scenes.py.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from shading_scenes import (
    COLOR, EFFECT_SETS, ROT, Scene, jaxpr_primitives, rgb_of, scene_params, used_inputs,
)

from albedo_model.params import DirectionalLight, SHLight
from albedo_model.shading.image_formation import (
    PACKED_SIZE, Effects, ShadingParams, combine_pixels, pack_shading_params, pixel_light,
    pixel_shader_function, shade, shade_pixels, shading_params, unpack_shading_params,
)
from albedo_model.shading.interpolation import interpolate_albedo, interpolate_geometry, pixel_hits


def _split_shade(effects, s: Scene, sp, shadow=None):
    tri, nrm, dif, spec, pid, bary, dirs = s.args()
    hits = pixel_hits(tri, pid, bary)
    geometry = interpolate_geometry(effects, hits, nrm, dirs, sp.rotation)
    albedo = interpolate_albedo(effects, hits, dif, spec)
    return hits, geometry, albedo, shade_pixels(effects, geometry, albedo, sp, shadow)


def test_interpolated_pixel_attributes_match_numpy():
    s = Scene(11)
    sp = shading_params(scene_params(), ROT)
    hits, geometry, albedo, _ = _split_shade(Effects(specular=True), s, sp)
    hit = s.prim_id >= 0
    np.testing.assert_array_equal(np.asarray(hits.mask), hit)
    n = s.interp(s.normals) @ ROT.T
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    got = np.stack([np.asarray(c) for c in geometry.normal], 1)
    np.testing.assert_allclose(got[hit], n[hit], atol=1e-6)
    v = -s.ray_dirs / np.linalg.norm(s.ray_dirs, axis=1, keepdims=True)
    np.testing.assert_allclose(np.stack([np.asarray(c) for c in geometry.view], 1), v, atol=1e-6)
    for got, want in ((albedo.diffuse, s.diffuse), (albedo.specular, s.specular)):
        np.testing.assert_allclose(np.stack([np.asarray(c) for c in got], 1)[hit],
                                   s.interp(want)[hit], atol=1e-6)
    # attributes an effect set does not read are not computed
    _, geometry, albedo, _ = _split_shade(Effects(), s, sp)
    assert geometry.view is None and albedo.specular is None


@pytest.mark.parametrize("effects", EFFECT_SETS, ids=str)
def test_shade_pixels_equals_full_shader(effects):
    s = Scene(12)
    rng = np.random.default_rng(13)
    light = SHLight(rng.normal(0, 0.25, (9, 3)) + SHLight.frontal().coefficients)
    dl = DirectionalLight((0.1, 0.1, 0.2), (0.5, 0.4, 0.3), (0.3, 0.2, 1.0), (0.2, 0.1, 0.1), 12.)
    sp = shading_params(scene_params(light, dl, COLOR, exponent=10.0), ROT, background=(0, 0.5, 1))
    shadow = jnp.asarray(s.shadow)
    *_, split = _split_shade(effects, s, sp, shadow)
    full = shade(effects, *s.args(), sp, shadow)
    np.testing.assert_array_equal(np.asarray(split.mask), np.asarray(full.mask))
    np.testing.assert_allclose(rgb_of(split), rgb_of(full), atol=1e-6)


def test_packed_shading_params_round_trip():
    dl = DirectionalLight((0.1, 0.2, 0.3), (0.5, 0.4, 0.3), (0.0, 0.6, 0.8), (0.05, 0.1, 0.0), 7.)
    p = scene_params(SHLight(np.arange(12.0).reshape(4, 3)), dl, COLOR, exponent=13.0)
    packed = pack_shading_params(p, ROT, background=(0.1, 0.2, 0.3))
    assert packed.shape == (PACKED_SIZE,) and packed.dtype == np.float32
    want = {
        "rotation": ROT, "sh": np.vstack([np.arange(12.0).reshape(4, 3), np.zeros((5, 3))]),
        "specular_exponent": 13.0, "light_direction": dl.direction, "light_ambient": dl.ambient,
        "light_diffuse": dl.diffuse, "light_specular": dl.specular, "light_shininess": 7.0,
        "color_gain": COLOR.gain, "color_contrast": COLOR.contrast, "color_offset": COLOR.offset,
        "background": (0.1, 0.2, 0.3),
    }
    assert set(want) == set(ShadingParams._fields)
    unpacked = jax.jit(unpack_shading_params)(packed)
    for got in (unpacked, shading_params(p, ROT, background=(0.1, 0.2, 0.3))):
        for name, value in want.items():
            np.testing.assert_array_equal(np.asarray(getattr(got, name)),
                                          np.asarray(value, np.float32), err_msg=name)


def _trace_pixels(effects):
    s = Scene(14)
    sp = shading_params(scene_params(), ROT)
    tri, nrm, dif, spec, pid, bary, dirs = s.args()
    hits = pixel_hits(tri, pid, bary)
    full = Effects(specular=True, directional=True, directional_specular_map=True)
    geometry = interpolate_geometry(full, hits, nrm, dirs, sp.rotation)
    albedo = interpolate_albedo(full, hits, dif, spec)
    args = (geometry, albedo, sp, jnp.asarray(s.shadow))
    closed = jax.make_jaxpr(pixel_shader_function(effects))(*args)
    leaves, _ = jax.tree_util.tree_flatten(args)
    names = (["mask"] + [f"normal{i}" for i in range(3)] + [f"view{i}" for i in range(3)]
             + [f"diffuse{i}" for i in range(3)] + [f"specular{i}" for i in range(3)]
             + list(ShadingParams._fields) + ["shadow"])
    assert len(names) == len(leaves)
    used = used_inputs(closed, len(leaves))
    return jaxpr_primitives(closed.jaxpr), {names[i] for i in used}


def test_pixel_shader_has_no_gathers_and_skips_switched_off_effects():
    prims_off, used_off = _trace_pixels(Effects())
    prims_spec, used_spec = _trace_pixels(Effects(specular=True))
    prims_all, used_all = _trace_pixels(Effects(specular=True, directional=True, shadows=True,
                                                color_transform=True, gamma=True))
    # a light step is a pure per-pixel evaluation: nothing is gathered
    for prims in (prims_off, prims_spec, prims_all):
        assert "gather" not in prims and "scatter-add" not in prims
    assert prims_off.count("exp") == 0 and prims_off.count("log") == 0
    assert prims_spec.count("exp") >= 1 and prims_spec.count("log") >= 1
    assert not used_off & {"view0", "specular0", "specular_exponent", "shadow", "light_direction",
                           "color_gain", "rotation"}
    assert {"view0", "specular0", "specular_exponent"} <= used_spec
    assert not used_spec & {"light_direction", "shadow", "color_gain"}
    assert {"shadow", "light_direction", "light_shininess", "color_gain",
            "color_offset"} <= used_all
    assert prims_all.count("log") > prims_spec.count("log")


def test_light_transport_times_albedo_is_the_image():
    """shade_pixels = combine(pixel_light(geometry), albedo), and the light reads no albedo."""
    s = Scene(15)
    rng = np.random.default_rng(16)
    light = SHLight(rng.normal(0, 0.25, (9, 3)) + SHLight.frontal().coefficients)
    dl = DirectionalLight((0.1, 0.1, 0.2), (0.5, 0.4, 0.3), (0.3, 0.2, 1.0), (0.2, 0.1, 0.1), 12.)
    sp = shading_params(scene_params(light, dl, COLOR, exponent=10.0), ROT)
    shadow = jnp.asarray(s.shadow)
    for eff in (Effects(), Effects(specular=True, color_transform=True),
                Effects(specular=True, directional=True, shadows=True, gamma=True),
                Effects(directional=True, directional_specular_map=True)):
        _, geometry, albedo, full = _split_shade(eff, s, sp, shadow)
        transport = pixel_light(eff, geometry, sp, shadow)
        assert (transport.specular is None) == (not (eff.specular or eff.directional_specular_map))
        assert (transport.constant is None) == (not eff.directional or eff.directional_specular_map)
        out = combine_pixels(eff, transport, albedo, geometry.mask, sp)
        np.testing.assert_allclose(rgb_of(out), rgb_of(full), atol=1e-6)
        # linear in the albedo: doubling it (without clamp or transform) doubles D + S
        if not (eff.color_transform or eff.gamma or eff.directional):
            twice = albedo._replace(diffuse=tuple(2 * c for c in albedo.diffuse),
                                    specular=None if albedo.specular is None
                                    else tuple(2 * c for c in albedo.specular))
            lin = eff._replace(clamp=False)
            a = rgb_of(combine_pixels(lin, transport, albedo, geometry.mask, sp))
            b = rgb_of(combine_pixels(lin, transport, twice, geometry.mask, sp))
            hit = s.prim_id >= 0
            np.testing.assert_allclose(b[hit], 2 * a[hit], rtol=1e-6, atol=1e-7)
    closed = jax.make_jaxpr(functools.partial(pixel_light, Effects(specular=True)))(
        geometry, sp, shadow)
    prims = jaxpr_primitives(closed.jaxpr)
    assert "gather" not in prims and prims.count("exp") >= 1
