"""Per-view sampling against analytic sphere scenes (exact images, no renderer)."""

from __future__ import annotations

import numpy as np
import pytest
from lightstage_scenes import (
    look_at,
    ray_clearance,
    render_spheres,
    sphere_colour,
    sphere_mesh,
    union,
)

from albedo_model.errors import InputError
from pipeline.texturing.triangle_coverage import coverage_mask
from pipeline.texturing.view_sampling import bilinear_sample, sample_view, sample_views, silhouette_distance

pytestmark = pytest.mark.embree

BIG = (np.zeros(3), 1.0)
SMALL = (np.array([0.25, 0.15, 1.6]), 0.3)
EYE = np.array([0.0, 0.0, 5.0])
FOCAL = 735.0  # the unit sphere at distance 5 spans ~150 px of radius


@pytest.fixture(scope="module")
def scene():
    cam = look_at(EYE, [0, 0, 0], [0, 1, 0], focal_px=FOCAL, size=(400, 420))
    image = render_spheres(cam, [BIG, SMALL])
    big_v, big_t = sphere_mesh(*BIG, subdivisions=4)
    small_v, small_t = sphere_mesh(*SMALL, subdivisions=3)
    vertices, triangles = union((big_v, big_t), (small_v, small_t))
    return cam, image, vertices, triangles, len(big_v)


def test_bilinear_is_exact_on_bilinear_images():
    h, w = 7, 9
    rows, cols = np.mgrid[0:h, 0:w].astype(float)
    img = np.stack([0.1 + 0.02 * cols, 0.3 + 0.05 * rows, 0.01 * cols * rows], axis=2)
    rng = np.random.default_rng(0)
    uv = np.concatenate([rng.uniform([0, 0], [w - 1, h - 1], (50, 2)),
                         [[w - 1, h - 1], [0, 0], [w - 0.5, 2], [-0.1, 3], [np.nan, 1]]])
    values, inside = bilinear_sample(img, uv)
    u, v = uv[:, 0], uv[:, 1]
    truth = np.stack([0.1 + 0.02 * u, 0.3 + 0.05 * v, 0.01 * u * v], axis=1)
    assert inside.tolist() == [True] * 52 + [False] * 3
    np.testing.assert_allclose(values[inside], truth[inside], atol=1e-6)
    assert (values[~inside] == 0).all()


def test_bilinear_scales_integer_images():
    img8 = np.full((4, 4, 3), 255, np.uint8)
    img16 = np.full((4, 4, 3), 65535, np.uint16)
    for img in (img8, img16):
        values, _ = bilinear_sample(img, np.array([[1.5, 2.25]]))
        np.testing.assert_allclose(values, 1.0, atol=1e-6)


def test_coverage_matches_brute_force():
    rng = np.random.default_rng(5)
    tri = rng.uniform(-3, 33, (25, 3, 2))
    tri[::3] = tri[::3] * 0.2 + 10  # small ones
    tri[1] = [[0, 0], [29, 0], [0, 19]]  # pixel centres exactly on two edges
    mask = coverage_mask(tri, (20, 30))
    rows, cols = np.mgrid[0:20, 0:30]
    ref = np.zeros((20, 30), bool)
    for (x0, y0), (x1, y1), (x2, y2) in tri:
        e = [(bx - ax) * (rows - ay) - (by - ay) * (cols - ax)
             for ax, ay, bx, by in ((x0, y0, x1, y1), (x1, y1, x2, y2), (x2, y2, x0, y0))]
        ref |= ((e[0] >= 0) & (e[1] >= 0) & (e[2] >= 0)) | ((e[0] <= 0) & (e[1] <= 0) & (e[2] <= 0))
    assert ref.any() and not ref.all()
    np.testing.assert_array_equal(mask, ref)


def test_silhouette_distance_of_a_sphere(scene):
    cam, _, vertices, triangles, n_big = scene
    dist, small = silhouette_distance(cam, vertices[:n_big], triangles[triangles.max(1) < n_big],
                                      mask_scale=2)
    radius_px = FOCAL * np.tan(np.arcsin(1.0 / 5.0))
    h, w = small.image_size
    rows, cols = np.mgrid[0:h, 0:w]
    # reduced pixel centres in full-resolution coordinates
    rho = np.hypot(cols * 2 + 0.5 - cam.principal_px[0], rows * 2 + 0.5 - cam.principal_px[1])
    inner = rho < radius_px - 4
    np.testing.assert_allclose(dist[inner], (radius_px - rho)[inner], atol=2.5)
    assert (dist[rho > radius_px + 2] == 0).all()


def test_sampling_validity_and_colours(scene):
    cam, image, vertices, triangles, n_big = scene
    threshold = 20.0
    s = sample_view(image, cam, vertices, triangles, boundary_distance_px=threshold, mask_scale=2)
    big = np.arange(n_big)
    p = vertices[big]
    normal = p / np.linalg.norm(p, axis=1, keepdims=True)
    to_eye = EYE - p
    cosine = np.einsum("ij,ij->i", normal, to_eye) / np.linalg.norm(to_eye, axis=1)
    uv = cam.project(p)
    radius_px = FOCAL * np.tan(np.arcsin(1.0 / 5.0))
    margin = radius_px - np.hypot(*(uv - cam.principal_px).T)  # distance to the silhouette
    clearance = ray_clearance(p, EYE, *SMALL)
    sure_valid = (cosine > 0.02) & (margin > threshold + 3) & (clearance > 0.01)
    sure_invalid = (cosine < -0.02) | (margin < threshold - 3) | (clearance < -0.01)
    assert sure_valid.sum() > 300 and (sure_invalid & (clearance < -0.01)).sum() > 50
    assert s.valid[big][sure_valid].all()
    assert not s.valid[big][sure_invalid].any()
    np.testing.assert_allclose(s.weight[big][sure_valid], cosine[sure_valid], atol=5e-3)
    assert (s.weight[~s.valid] == 0).all() and (s.weight[s.valid] > 0).all()
    # colours: exact texture of the big sphere, away from the occluder's outline
    clear = s.valid[big] & (clearance > 0.05)
    np.testing.assert_allclose(s.colour[big][clear], sphere_colour(p[clear], *BIG), atol=2e-3)


def test_sampling_with_lens_distortion():
    cam = look_at(EYE, [0, 0, 0], [0, 1, 0], focal_px=FOCAL, size=(400, 420),
                  distortion=(-0.3, 0.8, 0.0, 0.002, -0.003))
    image = (render_spheres(cam, [BIG]) * 255).round().astype(np.uint8)
    v, t = sphere_mesh(*BIG, subdivisions=4)
    [s] = sample_views([image], [cam], v, t, boundary_distance_px=10.0)
    assert s.valid.sum() > 500
    # 8-bit quantisation (0.002) plus bilinear error
    np.testing.assert_allclose(s.colour[s.valid], sphere_colour(v[s.valid], *BIG), atol=4e-3)


def test_wrong_image_size(scene):
    cam, image, vertices, triangles, _ = scene
    with pytest.raises(InputError, match="camera expects 420x400"):
        sample_view(image[:-1], cam, vertices, triangles)


def test_timings_are_recorded(scene):
    cam, image, vertices, triangles, _ = scene
    timings: dict = {}
    sample_views([image, image], [cam, cam], vertices, triangles, timings=timings)
    assert set(timings) == {"sampling", "silhouette", "visibility"}
    assert all(t >= 0 for t in timings.values())
