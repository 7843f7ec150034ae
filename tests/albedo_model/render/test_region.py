"""The interior region of a ray cast: erosion from the silhouette, bands around occlusion contours."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from albedo_model.render.region import depth_contours, interior_region

W, H = 60, 50


def _disk(radius=18.0, centre=(25.0, 30.0)):
    yy, xx = np.mgrid[0:H, 0:W]
    return (yy - centre[0]) ** 2 + (xx - centre[1]) ** 2 <= radius ** 2


def test_erosion_keeps_pixels_farther_than_erode_from_a_miss():
    hit = _disk()
    prim = np.where(hit, 7, -1).reshape(-1)
    t = np.where(hit, 1000.0, np.inf).reshape(-1)
    for erode in (0, 1, 2, 4):
        region = interior_region(prim, t, W, H, erode=erode).reshape(H, W)
        # brute force: city-block distance (4-connected steps) to the nearest miss
        dist = ndimage.distance_transform_cdt(hit, metric="taxicab")
        np.testing.assert_array_equal(region, hit & (dist > erode))


def test_a_smooth_slope_is_not_a_contour_but_a_step_in_depth_is():
    hit = np.ones((H, W), bool)
    yy, xx = np.mgrid[0:H, 0:W]
    ramp = 1000.0 + 2.0 * xx  # 0.2 % per pixel: a steep but continuous surface
    prim = np.zeros(H * W, int)
    assert not depth_contours(prim, ramp.reshape(-1), W, H).any()
    step = np.where(xx < 30, 1000.0, 1040.0)  # a 4 % jump: one surface in front of another
    contour = depth_contours(prim, step.reshape(-1), W, H)
    assert set(np.unique(np.nonzero(contour)[1])) == {29, 30}
    region = interior_region(prim, step.reshape(-1), W, H, erode=0, contour_band=2).reshape(H, W)
    cols = np.flatnonzero(~region.all(axis=0))
    np.testing.assert_array_equal(cols, np.arange(27, 33))  # the contour and 2 px each side


def test_usable_mask_and_empty_cast():
    hit = _disk()
    prim = np.where(hit, 1, -1).reshape(-1)
    t = np.where(hit, 900.0, np.inf).reshape(-1)
    usable = np.ones(H * W, bool)
    usable[:W * 25] = False  # top half unusable (e.g. saturated target)
    region = interior_region(prim, t, W, H, usable=usable)
    assert region.any() and not region[:W * 25].any()
    none = interior_region(np.full(H * W, -1), np.full(H * W, np.inf), W, H)
    assert not none.any()
