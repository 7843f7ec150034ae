"""The interior region of a ray cast: erosion from the silhouette, bands around occlusion contours."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

import pytest

from albedo_model.render.region import depth_contours, fold_contours, fold_edges, interior_region

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


# -- fold edges: the mesh's occlusion contours ------------------------------------------

def _facing_reference(mesh, eye):
    """Brute force with trimesh: face adjacency, and which faces see ``eye``."""
    front = np.einsum("ij,ij->i", mesh.face_normals, eye - mesh.triangles_center) > 0
    pairs = mesh.face_adjacency
    folds = {tuple(sorted(e)) for e, (a, b) in zip(mesh.face_adjacency_edges, pairs)
             if front[a] != front[b]}
    # edges of one face only: the rim of an open mesh
    edges = np.sort(mesh.edges, axis=1)
    uniq, count = np.unique(edges, axis=0, return_counts=True)
    return folds | {tuple(e) for e in uniq[count == 1]}


@pytest.mark.parametrize("open_mesh", [False, True])
def test_fold_edges_match_trimesh_face_adjacency(open_mesh):
    import trimesh

    mesh = trimesh.creation.icosphere(subdivisions=3, radius=40.0)
    if open_mesh:  # cut a cap off: its rim counts as a fold
        keep = mesh.triangles_center[:, 2] < 25.0
        mesh = trimesh.Trimesh(mesh.vertices, mesh.faces[keep], process=False)
    eye = np.array([30.0, -20.0, 400.0])
    got = {tuple(e) for e in fold_edges(mesh.vertices, mesh.faces, eye)}
    assert got == _facing_reference(mesh, eye)
    # the sphere's folds lie on its outline seen from the eye (within one edge length)
    centre_dist = np.linalg.norm(eye)
    tangent_angle = np.arccos(40.0 / centre_dist)
    mids = np.array([mesh.vertices[list(e)].mean(0) for e in got
                     if not open_mesh or mesh.vertices[list(e)][:, 2].max() < 20.0])
    angle = np.arccos(mids @ eye / (np.linalg.norm(mids, axis=1) * centre_dist))
    assert np.all(np.abs(angle - tangent_angle) < 0.2)


def test_fold_contours_find_a_fold_with_no_depth_jump():
    """A sheet folded over itself 0.5 mm in front: invisible to the depth test, found by the folds."""
    from albedo_model.camera import camera_rays, project
    from albedo_model.params import default_square, fit_to_image_size
    from albedo_model.render.raycast import RayCaster

    # Z-fold in x (mm): A at z=0 for x in [-60, 10], B back from (10, 0) to (0, 0.5),
    # C at z=0.5 for x in [0, 60]; C hides A's part in [0, 10] with a 0.5 mm gap
    ys = np.linspace(-40.0, 40.0, 9)
    xs_a, xs_c = np.linspace(-60.0, 10.0, 15), np.linspace(0.0, 60.0, 13)
    rows = [(xs_a, 0.0), (np.array([10.0, 0.0]), None), (xs_c, 0.5)]
    verts, strips = [], []
    for xs, z in rows:
        zs = np.linspace(0.0, 0.5, xs.size) if z is None else np.full(xs.size, z)
        start = len(verts)
        verts += [(x, y, zz) for x, zz in zip(xs, zs) for y in ys]
        strips.append((start, xs.size))
    verts = np.array(verts)
    tris = []
    for start, n in strips:
        for i in range(n - 1):
            for j in range(ys.size - 1):
                a, b = start + i * ys.size + j, start + (i + 1) * ys.size + j
                tri1, tri2 = (a, b, b + 1), (a, b + 1, a + 1)
                tris += [tri1, tri2]
    # stitch the strips: the last column of one is the first of the next
    v = verts.copy()
    key: dict = {}
    remap = np.arange(len(v))
    for i, p in enumerate(map(tuple, np.round(v, 6))):
        remap[i] = key.setdefault(p, i)
    tris = remap[np.array(tris)]
    # each strip's winding faces +z; B runs backwards in x, so it faces -z: a fold at x=0, x=10
    size = 96
    params = fit_to_image_size(default_square(), size, size)
    params = params._replace(pose=params.pose._replace(translation=(0.0, 0.0, -1000.0)))
    caster = RayCaster(np.ascontiguousarray(v, np.float32), tris, threads=1)
    o, d = camera_rays(params.camera, params.image_size, params.pose, params.view)
    hits = caster.cast(o, d, tfar=float(params.camera.far - params.camera.near),
                       cull_backfaces=False, image_shape=(size, size))
    prim, t = np.asarray(hits.prim_id), np.asarray(hits.t)
    depth_only = interior_region(prim, t, size, size, erode=0, contour_band=0)
    folds = fold_contours(params, v, tris, t)
    with_folds = interior_region(prim, t, size, size, erode=0, contour_band=0, folds=folds)
    col = lambda x: int(round(project(np.array([[x, 0.0, 0.5]]), params.pose, params.view,
                                      params.camera, params.image_size)[0][0, 0]))
    centre = size // 2  # an image row across the sheet
    assert depth_only.reshape(size, size)[centre, col(0)]  # the depth test does not see it
    assert not with_folds.reshape(size, size)[centre, col(0)]  # the fold does
    assert with_folds.reshape(size, size)[centre, col(-30)]  # flat sheet away from folds
    assert with_folds.reshape(size, size)[centre, col(40)]
