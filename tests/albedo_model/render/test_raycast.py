"""Embree ray caster against the brute-force z-buffer reference, and its input checks.

Hits, back-face culling, fast against robust traversal, threads, occlusion and
visibility, bad input, pixel windows. Refit and double buffering:
test_raycast_refit.py; meshes and poses: raycast_meshes.py.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("embreex")
pytest.importorskip("trimesh")

from albedo_model import camera as cam  # noqa: E402
from albedo_model.render import raycast  # noqa: E402
from albedo_model.errors import InputError  # noqa: E402
from albedo_model.params import Camera, ImageSize, Pose, View  # noqa: E402

from raycast_meshes import MESHES, POSES, bumpy_sphere, icosphere, open_shell, scene  # noqa: E402
from zbuffer_reference import render_zbuffer  # noqa: E402

pytestmark = pytest.mark.embree


def compare_to_zbuffer(v, f, pose, camera, size, caster=None):
    prim_z, bary_z, depth_z = render_zbuffer(v, f, pose, View(), camera, size)
    caster = caster or raycast.RayCaster(v, f)
    o, d = cam.camera_rays(camera, size, pose, View())
    hits = caster.cast(o, d, tfar=camera.far - camera.near, image_shape=(size.height, size.width))
    prim = hits.prim_id.reshape(size.height, size.width)
    bary = hits.bary.reshape(size.height, size.width, 2).astype(np.float64)
    attr = (v - v.min(0)) / np.ptp(v, 0)  # a smooth per-vertex value in [0, 1]

    def interp(p, b, sel):
        t = f[p[sel]]
        b = b[sel]
        return ((1 - b[:, :1] - b[:, 1:]) * attr[t[:, 0]] + b[:, :1] * attr[t[:, 1]]
                + b[:, 1:] * attr[t[:, 2]])

    both = (prim_z >= 0) & (prim >= 0)
    err = np.abs(interp(prim_z, bary_z, both) - interp(prim, bary, both)).max(1)
    same = prim_z[both] == prim[both]
    depth = hits.t.reshape(prim.shape)[both] + camera.near
    return dict(
        coverage=(prim_z >= 0).mean(), mask=((prim_z >= 0) == (prim >= 0)).mean(),
        prim=same.mean(), err_same=err[same].max(), err=err, bary=hits.bary, t=hits.t,
        depth=np.abs(depth - depth_z[both]).max(),
    )


@pytest.mark.parametrize("pose_name", POSES)
@pytest.mark.parametrize("mesh_name", MESHES)
def test_matches_zbuffer(mesh_name, pose_name):
    v, f = MESHES[mesh_name]()
    pose, size, pp, ortho = POSES[pose_name]
    r = compare_to_zbuffer(v, f, pose, scene(size, pp, ortho), size)
    assert r["coverage"] > 0.005
    assert r["mask"] >= 0.995
    assert r["prim"] >= 0.995
    assert r["err_same"] <= 1e-4
    assert np.quantile(r["err"], 0.995) <= 1e-4
    assert r["depth"] < 1e-2  # mm, float32 rays at ~1 m
    assert np.isfinite(r["bary"]).all()


def test_open_mesh_from_behind_is_culled_like_scalismo():
    v, f = open_shell()
    pose, size, pp, ortho = POSES["behind"]
    camera = scene(size, pp, ortho)
    o, d = cam.camera_rays(camera, size, pose, View())
    caster = raycast.RayCaster(v, f)
    culled = caster.cast(o, d).mask
    unculled = caster.cast(o, d, cull_backfaces=False).mask
    prim_z, _, _ = render_zbuffer(v, f, pose, View(), camera, size, cull=True)
    assert unculled.sum() > 5 * culled.sum() > 0  # mostly the inside of the shell is seen
    assert ((prim_z.reshape(-1) >= 0) == culled).mean() >= 0.995


def test_real_head_mesh(shared_data):
    h5py = pytest.importorskip("h5py")
    path = shared_data / "scalismo" / "random-l4.h5"
    if not path.exists():
        pytest.skip(f"{path} not found")
    with h5py.File(path, "r") as h5:
        v = h5["shape/representer/points"][:].T.astype(np.float64)
        f = h5["shape/representer/cells"][:].T.astype(np.int64)
    size = ImageSize(100, 120)
    pose = Pose(translation=(3.1, -20.7, -1000.0), yaw=0.5, pitch=0.1, roll=-0.05)
    r = compare_to_zbuffer(v, f, pose, scene(size, (0.03, -0.02)), size)
    assert r["coverage"] > 0.2
    assert r["mask"] >= 0.995 and r["prim"] >= 0.995
    assert np.quantile(r["err"], 0.995) <= 1e-4


def test_nonrobust_with_grid_equals_robust():
    v, f = bumpy_sphere()
    fast = raycast.RayCaster(v, f, robust=False)
    robust = raycast.RayCaster(v, f, robust=True)
    rng = np.random.default_rng(0)
    size = ImageSize(128, 128)
    camera = scene(size)
    for _ in range(10):
        pose = Pose(translation=(rng.normal(0, 30), rng.normal(0, 30), -1000 + rng.normal(0, 100)),
                    roll=rng.normal(0, 1), yaw=rng.normal(0, 1), pitch=rng.normal(0, 1))
        o, d = cam.camera_rays(camera, size, pose, View())
        a = fast.cast(o, d, image_shape=(128, 128))
        b = robust.cast(o, d)
        np.testing.assert_array_equal(a.mask, b.mask)
        assert (a.prim_id == b.prim_id).mean() > 0.999


def test_threads_give_identical_hits():
    v, f = bumpy_sphere()
    size = ImageSize(100, 100)
    o, d = cam.camera_rays(scene(size), size, Pose(yaw=0.4), View())
    one, two = raycast.RayCaster(v, f, threads=1), raycast.RayCaster(v, f, threads=2)
    for x, y in zip(one.cast(o, d), two.cast(o, d)):
        np.testing.assert_array_equal(x, y)
    tmax = np.random.default_rng(0).uniform(800, 1100, len(o))
    occ = one.occluded(o, d, tmax)
    assert 0.05 < occ.mean() < 0.5
    np.testing.assert_array_equal(occ, two.occluded(o, d, tmax))
    np.testing.assert_array_equal(one.occluded(o, d[:1]), two.occluded(o, d[:1]))


def test_visible_points_front_and_back():
    v, f = icosphere()
    caster = raycast.RayCaster(v, f)
    pose = Pose(yaw=0.7)
    eye = cam.eye_position_model(pose, View())
    toward = eye / np.linalg.norm(eye)
    on_surface = v[np.abs(v @ toward) > 30]  # away from the silhouette
    vis = raycast.visible_points(on_surface, eye, caster)
    np.testing.assert_array_equal(vis, on_surface @ toward > 0)
    ortho = raycast.visible_points(on_surface, None, caster, direction=toward)
    np.testing.assert_array_equal(ortho, on_surface @ toward > 0)
    # a point behind a blocking sphere, and the same point beside it
    assert not raycast.visible_points([[0, 0, 0]] - 300 * toward[None], eye, caster)[0]
    assert raycast.visible_points([[0, 250, 0]] - 300 * toward[None], eye, caster)[0]


def test_occluded_segments():
    v, f = icosphere()
    caster = raycast.RayCaster(v, f)
    o = np.array([[0, 0, 500], [0, 0, 500], [0, 300, 500]], np.float32)
    d = np.array([[0, 0, -1]], np.float32)
    np.testing.assert_array_equal(caster.occluded(o, d), [True, True, False])
    np.testing.assert_array_equal(caster.occluded(o, d, np.array([350, 450, 1e3])),
                                  [False, True, False])


def test_degenerate_triangles_give_no_nan():
    v, f = icosphere()
    n = len(v)
    v2 = np.vstack([v, v[:10]])  # duplicate vertices
    extra = np.array([[0, 0, 1], [n, 0, 5], [1, n + 1, 1], [2, 3, 2]])  # zero-area triangles
    f2 = np.vstack([f, extra, f[:5] + 0 * f[:5]])
    f2[-5:, 0] = f2[-5:, 1]  # more degenerate copies
    size = ImageSize(64, 64)
    camera = scene(size)
    pose = Pose(translation=(0.3, 0.2, -1000))
    caster = raycast.RayCaster(v2, f2)
    o, d = cam.camera_rays(camera, size, pose, View())
    hits = caster.cast(o, d, image_shape=(64, 64))
    assert np.isfinite(hits.bary).all() and np.isfinite(hits.t[hits.mask]).all()
    assert not np.isin(hits.prim_id, np.arange(len(f), len(f2))).any()
    r = compare_to_zbuffer(v2, f2, pose, camera, size, caster)
    assert r["mask"] >= 0.995
    caster.update_vertices(v2 * 1.01)
    assert np.isfinite(caster.cast(o, d).bary).all()


def test_bad_input():
    v, f = icosphere()
    with pytest.raises(InputError):
        raycast.RayCaster(v[:, :2], f)
    with pytest.raises(InputError):
        raycast.RayCaster(v, f + len(v))
    caster = raycast.RayCaster(v, f)
    with pytest.raises(InputError):
        caster.update_vertices(v[:-1])
    bad = v.copy()
    bad[3, 1] = np.nan
    with pytest.raises(InputError):
        caster.update_vertices(bad)
    with pytest.raises(InputError):
        caster.cast(np.zeros((4, 3)), np.zeros((3, 3)))
    with pytest.raises(InputError):
        raycast.RayCaster(v, f, threads=3)
    with pytest.raises(InputError):
        caster.cast(np.zeros((6, 3)), np.zeros((6, 3)), image_shape=(2, 2))
    empty = caster.cast(np.zeros((0, 3)), np.zeros((0, 3)))
    assert empty.prim_id.shape == (0,) and empty.bary.shape == (0, 2)
    assert raycast.visible_points(np.zeros((0, 3)), np.ones(3), caster).shape == (0,)


def test_camera_dependence_of_cast_is_rays_only():
    """A pose change moves rays only: same hits as moving the mesh into the eye frame."""
    v, f = bumpy_sphere()
    pose = Pose(scaling=1.2, translation=(10, -5, -950), roll=0.2, yaw=-0.6, pitch=0.3)
    size = ImageSize(80, 80)
    camera = Camera(focal_length=7.5, sensor_size=(2.0, 2.0), near=10.0, far=1e6)
    o, d = cam.camera_rays(camera, size, pose, View())
    in_model = raycast.RayCaster(v, f).cast(o, d)
    v_eye = cam.to_eye(v, pose, View())
    o_e, d_e = cam.camera_rays(camera, size, Pose(translation=(0, 0, 0)), View())
    in_eye = raycast.RayCaster(v_eye, f).cast(o_e, d_e)
    assert (in_model.prim_id == in_eye.prim_id).mean() > 0.999
    both = in_model.mask & in_eye.mask
    np.testing.assert_allclose(in_model.t[both], in_eye.t[both], rtol=1e-4)


def test_raycast_is_the_only_embreex_importer():
    import ast

    root = Path(raycast.__file__).resolve().parents[2]
    importers = set()
    paths = [p for pkg in ("albedo_model", "proposals", "pipeline", "mcmcfit", "benchmarks")
             for p in (root / pkg).rglob("*.py")]
    for path in paths:
        for node in ast.walk(ast.parse(path.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            if any(n.split(".")[0] == "embreex" for n in names):
                importers.add(path.relative_to(root).as_posix())
    assert importers == {"albedo_model/render/raycast.py"}


@pytest.mark.parametrize("pose_name", POSES)
@pytest.mark.parametrize("mesh_name", MESHES)
def test_pixel_window_holds_every_hit_and_windowed_cast_is_identical(mesh_name, pose_name):
    v, f = MESHES[mesh_name]()
    pose, size, pp, ortho = POSES[pose_name]
    camera = scene(size, pp, ortho)
    caster = raycast.RayCaster(v, f)
    np.testing.assert_allclose(caster.bounds, [v.min(0), v.max(0)], rtol=1e-6)
    o, d = cam.camera_rays(camera, size, pose, View())
    shape = (size.height, size.width)
    full = caster.cast(o, d, tfar=camera.far - camera.near, image_shape=shape)
    window = cam.pixel_window(caster.bounds, camera, size, pose, View())
    assert window is not None
    y0, y1, x0, x1 = window
    ys, xs = np.nonzero(full.mask.reshape(shape))
    assert ys.min() >= y0 and ys.max() < y1 and xs.min() >= x0 and xs.max() < x1
    # a window strictly inside the image on at least one side, so that the
    # windowed path is taken for some of these cases
    windowed = caster.cast(o, d, tfar=camera.far - camera.near, image_shape=shape,
                           window=window)
    np.testing.assert_array_equal(windowed.prim_id, full.prim_id)
    np.testing.assert_array_equal(windowed.bary, full.bary)
    np.testing.assert_array_equal(windowed.t, full.t)


def test_pixel_window_small_far_face_and_degenerate_cases():
    v, f = bumpy_sphere(3)
    size = ImageSize(200, 160)
    camera = scene(size)
    caster = raycast.RayCaster(v, f)
    # a small face off-centre: a small window, and cutting columns too
    pose = Pose(translation=(-300.0, 150.0, -4000.0))
    o, d = cam.camera_rays(camera, size, pose, View())
    y0, y1, x0, x1 = cam.pixel_window(caster.bounds, camera, size, pose, View())
    assert (y1 - y0) * (x1 - x0) < 0.1 * size.width * size.height
    full = caster.cast(o, d, image_shape=(160, 200))
    cut = caster.cast(o, d, image_shape=(160, 200), window=(y0, y1, x0, x1))
    assert full.mask.sum() > 50
    np.testing.assert_array_equal(cut.prim_id, full.prim_id)
    # entirely outside the image: an empty window and no hits
    away = Pose(translation=(5000.0, 0.0, -1000.0))
    win = cam.pixel_window(caster.bounds, camera, size, away, View())
    assert win[0] == win[1] or win[2] == win[3]
    o2, d2 = cam.camera_rays(camera, size, away, View())
    assert not caster.cast(o2, d2, image_shape=(160, 200), window=win).mask.any()
    # the eye inside the box: projection bounds nothing, cast everything
    inside = Pose(translation=(0.0, 0.0, -50.0))
    assert cam.pixel_window(caster.bounds, camera, size, inside, View()) is None
    with pytest.raises(InputError, match="window"):
        caster.cast(o, d, image_shape=(160, 200), window=(0, 161, 0, 10))
    with pytest.raises(InputError, match="image_shape"):
        caster.cast(o, d, window=(0, 10, 0, 10))
