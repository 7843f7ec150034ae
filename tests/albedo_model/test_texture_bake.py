"""Baking per-vertex values into textures: brute force, an analytic field, round trips."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from albedo_model.errors import InputError
from albedo_model.texture.bake import bake_vertex_values, sample_texture, snapped_atlas
from albedo_model.uv_atlas import UVAtlas, compute_uv_atlas, uv_vertices

pytest.importorskip("xatlas")


@pytest.fixture(scope="module")
def sphere():
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=50.0)
    v, t = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    return v, t, compute_uv_atlas(v, t)


def _brute_force(atlas: UVAtlas, values_per_point: np.ndarray, size: int):
    """Each texel centre strictly inside one UV triangle, interpolated by explicit barycentrics."""
    centres = (np.arange(size) + 0.5)
    gy, gx = np.meshgrid(centres, centres, indexing="ij")
    out = np.full((size, size, values_per_point.shape[1]), np.nan)
    xy = np.stack([atlas.uv[:, 0] * size, (1 - atlas.uv[:, 1]) * size], 1)
    for tri in atlas.uv_triangles:
        a, b, c = xy[tri]
        m = np.array([b - a, c - a]).T
        if abs(np.linalg.det(m)) < 1e-9:
            continue
        lo = np.floor(np.min(xy[tri], 0)).astype(int)
        hi = np.ceil(np.max(xy[tri], 0)).astype(int)
        for r in range(max(lo[1], 0), min(hi[1], size)):
            for col in range(max(lo[0], 0), min(hi[0], size)):
                u, v = np.linalg.solve(m, np.array([gx[r, col], gy[r, col]]) - a)
                if min(u, v, 1 - u - v) > 1e-6:
                    out[r, col] = ((1 - u - v) * values_per_point[tri[0]]
                                   + u * values_per_point[tri[1]] + v * values_per_point[tri[2]])
    return out


def test_texels_inside_triangles_match_a_brute_force_interpolation(sphere):
    v, t, atlas = sphere
    values = np.random.default_rng(1).uniform(0, 1, (len(v), 3))
    size = 64
    baked = bake_vertex_values(atlas, t, values, size)
    owner = uv_vertices(atlas, t)
    ref = _brute_force(baked.atlas, values[owner], size)
    inside = ~np.isnan(ref[..., 0])
    assert inside.sum() > 0.3 * size * size
    assert np.all(baked.covered[inside])
    np.testing.assert_allclose(baked.image[inside], ref[inside], atol=2e-6)


def test_a_linear_field_is_sampled_back_exactly_anywhere_in_a_chart():
    # one planar chart whose UVs are the vertices' own x, y: a field linear in x, y is
    # linear in (u, v), which barycentric baking and bilinear sampling both keep exactly
    n = 9
    x, y = np.meshgrid(np.linspace(0.1, 0.9, n), np.linspace(0.1, 0.9, n))
    uv = np.stack([x.ravel(), y.ravel()], 1)
    tris = [(j * n + i, j * n + i + 1, (j + 1) * n + i + 1) for j in range(n - 1) for i in range(n - 1)]
    tris += [(j * n + i, (j + 1) * n + i + 1, (j + 1) * n + i) for j in range(n - 1) for i in range(n - 1)]
    tri = np.array(tris)
    field = lambda p: 0.2 + 0.5 * p[:, 0] - 0.3 * p[:, 1]  # noqa: E731
    size = 128
    atlas = UVAtlas(uv, tri)
    snapped = snapped_atlas(atlas, size)
    baked = bake_vertex_values(atlas, tri, field(snapped.uv), size)
    inner = np.random.default_rng(2).uniform(0.15, 0.85, (500, 2))
    np.testing.assert_allclose(sample_texture(baked.image, inner), field(inner), atol=1e-5)


def test_round_trip_at_the_vertices_and_a_full_gutter(sphere):
    v, t, atlas = sphere
    values = np.random.default_rng(3).uniform(0, 1, (len(v), 2))
    baked = bake_vertex_values(atlas, t, values, 256)
    assert baked.collisions == 0
    owner = uv_vertices(baked.atlas, t)
    np.testing.assert_allclose(sample_texture(baked.image, baked.atlas.uv), values[owner],
                               atol=1e-6)
    # the gutter holds chart values (no background to bleed in), within the values' range
    assert not baked.covered.all()
    assert baked.image.min() >= values.min() - 1e-6 and baked.image.max() <= values.max() + 1e-6
    # snapping moves each point by at most half a texel
    assert np.abs(baked.atlas.uv - atlas.uv).max() <= 0.5 / 256 + 1e-12


def test_a_one_channel_field_gives_a_two_dimensional_image(sphere):
    v, t, atlas = sphere
    baked = bake_vertex_values(atlas, t, np.linspace(0, 1, len(v)), 32)
    assert baked.image.shape == (32, 32)


def test_collisions_are_counted_when_the_texture_is_too_small(sphere):
    v, t, atlas = sphere
    assert bake_vertex_values(atlas, t, np.random.default_rng(0).uniform(size=len(v)), 16).collisions > 0


def test_the_default_model_round_trips_within_a_sixteen_bit_step():
    from mcmcfit.jobs.model_spec import load_model_spec

    model = load_model_spec("default-face", progress=False)
    assert model.uv_atlas is not None
    values = model.diffuse_instance(np.random.default_rng(4).standard_normal(model.diffuse.rank))
    baked = bake_vertex_values(model.uv_atlas, model.triangles, values, 1024)
    assert baked.collisions == 0
    owner = uv_vertices(baked.atlas, model.triangles)
    sixteen_bit = np.round(np.clip(baked.image, 0, 1) * 65535) / 65535
    err = np.abs(sample_texture(sixteen_bit, baked.atlas.uv) - np.clip(values[owner], 0, 1))
    assert err.max() <= 0.5 / 65535 + 1e-7
    assert baked.covered.mean() > 0.4  # the face's own atlas, not the head's restricted


@pytest.mark.parametrize(("values", "size", "message"), [
    (np.zeros((10, 3)), 64, "10 rows; the triangles index 162"),
    (np.full((162, 3), np.nan), 64, "finite"),
    (np.zeros((162, 3)), 8, ">= 16"),
    (np.zeros((162, 3)), 64.0, "integer"),
])
def test_bad_input_is_refused(sphere, values, size, message):
    _, t, atlas = sphere
    with pytest.raises(InputError, match=message):
        bake_vertex_values(atlas, t, values, size)
