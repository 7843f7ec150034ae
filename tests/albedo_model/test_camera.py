"""Camera geometry against hand-computed values and an OpenGL-style matrix pipeline."""

from __future__ import annotations

import numpy as np
import pytest

from albedo_model import camera as cam
from albedo_model.params import Camera, ImageSize, Pose, View


def test_euler_rotation_axes_and_order():
    x, y, z = np.eye(3)
    quarter = np.pi / 2
    np.testing.assert_allclose(cam.euler_rotation(quarter, 0, 0) @ x, y, atol=1e-15)  # roll: z
    np.testing.assert_allclose(cam.euler_rotation(0, quarter, 0) @ z, x, atol=1e-15)  # yaw: y
    np.testing.assert_allclose(cam.euler_rotation(0, 0, quarter) @ y, z, atol=1e-15)  # pitch: x
    # pitch is applied first: Rz(roll) Ry(yaw) Rx(pitch)
    roll, yaw, pitch = 0.3, -0.7, 1.1
    composed = (cam.euler_rotation(roll, 0, 0) @ cam.euler_rotation(0, yaw, 0)
                @ cam.euler_rotation(0, 0, pitch))
    r = cam.euler_rotation(roll, yaw, pitch)
    np.testing.assert_allclose(r, composed, atol=1e-15)
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-14)
    assert np.linalg.det(r) == pytest.approx(1.0)


def test_project_hand_computed_nonsquare_principal_point():
    camera = Camera(focal_length=7.5, sensor_size=(4.0, 2.0), near=10.0, far=1e6,
                    principal_point=(0.1, -0.2))
    size = ImageSize(200, 100)
    px, depth = cam.project(np.array([[10.0, 20.0, 0.0]]), Pose(), View(), camera, size)
    # u = 200/2 (1 + 0.1) + (200 * 7.5 / 4) * 10 / 1000
    # v = 100/2 (1 + 0.2) - (100 * 7.5 / 2) * 20 / 1000
    np.testing.assert_allclose(px, [[113.75, 52.5]], rtol=0, atol=1e-12)
    # OpenGL window depth = f (d - n) / (d (f - n)) at eye distance d = 1000
    assert depth[0] == pytest.approx(1e6 * 990.0 / (1000.0 * (1e6 - 10.0)), rel=1e-12)


def test_project_orthographic_uses_scale_at_near():
    camera = Camera(focal_length=5.0, sensor_size=(2.0, 3.0), near=500.0, far=2000.0,
                    principal_point=(-0.3, 0.4), orthographic=True)
    size = ImageSize(64, 96)
    pts = np.array([[10.0, -20.0, 0.0], [10.0, -20.0, -300.0]])
    px, depth = cam.project(pts, Pose(translation=(0, 0, -1000)), View(), camera, size)
    u = 32 * (1 - 0.3) + (64 * 5.0 / 2.0) * 10 / 500
    v = 48 * (1 - 0.4) - (96 * 5.0 / 3.0) * -20 / 500
    np.testing.assert_allclose(px, [[u, v], [u, v]], atol=1e-12)  # independent of depth
    # orthographic depth is linear: (d - n) / (f - n)
    np.testing.assert_allclose(depth, [500 / 1500, 800 / 1500], atol=1e-12)


def test_depth_limits_and_inverse():
    camera = Camera(near=10.0, far=5000.0)
    limits = cam.ndc_depth(np.array([10.0, 5000.0]), camera)
    np.testing.assert_allclose(limits, [0.0, 1.0], atol=1e-12)
    d = np.array([12.0, 100.0, 999.0, 4000.0])
    np.testing.assert_allclose(cam.eye_depth(cam.ndc_depth(d, camera), camera), d, rtol=1e-9)
    assert np.all(np.diff(cam.ndc_depth(d, camera)) > 0)


def _opengl_reference(points, pose, view, camera, size):
    """Homogeneous 4x4 pipeline: model, view, frustum (glFrustum with off-centre), window."""
    def rot4(roll, yaw, pitch):
        m = np.eye(4)
        m[:3, :3] = cam.euler_rotation(roll, yaw, pitch)
        return m

    def trans4(t):
        m = np.eye(4)
        m[:3, 3] = t
        return m

    model = trans4(pose.translation) @ rot4(pose.roll, pose.yaw, pose.pitch) @ np.diag(
        [pose.scaling] * 3 + [1.0])
    view_m = np.linalg.inv(trans4(view.translation) @ rot4(view.roll, view.yaw, view.pitch))
    n, f = camera.near, camera.far
    half_h = n * camera.sensor_size[1] / camera.focal_length / 2
    half_w = n * camera.sensor_size[0] / camera.focal_length / 2
    ppx, ppy = camera.principal_point
    l, r = -half_w * (1 + ppx), half_w * (1 - ppx)
    b, t = -half_h * (1 + ppy), half_h * (1 - ppy)
    proj = np.array([
        [2 * n / (r - l), 0, (r + l) / (r - l), 0],
        [0, 2 * n / (t - b), (t + b) / (t - b), 0],
        [0, 0, -(f + n) / (f - n), -2 * f * n / (f - n)],
        [0, 0, -1, 0]])
    h = np.c_[points, np.ones(len(points))] @ (proj @ view_m @ model).T
    ndc = h[:, :3] / h[:, 3:]
    u = size.width / 2 * (ndc[:, 0] + 1)
    v = size.height / 2 * (1 - ndc[:, 1])
    return np.stack([u, v], 1), (ndc[:, 2] + 1) / 2


def test_project_matches_matrix_pipeline_with_pose_and_view():
    rng = np.random.default_rng(3)
    pts = rng.normal(0, 60, (50, 3))
    pose = Pose(scaling=1.3, translation=(15.0, -40.0, -900.0), roll=0.4, yaw=-0.9, pitch=0.25)
    view = View(translation=(30.0, 10.0, 50.0), roll=0.05, yaw=0.1, pitch=-0.08)
    camera = Camera(focal_length=9.0, sensor_size=(3.0, 2.0), near=20.0, far=1e5,
                    principal_point=(0.12, -0.07))
    size = ImageSize(150, 100)
    px, depth = cam.project(pts, pose, view, camera, size)
    ref_px, ref_depth = _opengl_reference(pts, pose, view, camera, size)
    np.testing.assert_allclose(px, ref_px, atol=1e-9)
    np.testing.assert_allclose(depth, ref_depth, atol=1e-12)


def test_view_translation_moves_camera():
    camera = Camera()
    size = ImageSize(100, 100)
    view = View(translation=(100.0, -50.0, 0.0))
    px, _ = cam.project(np.zeros((1, 3)), Pose(translation=(100.0, -50.0, -800.0)), view, camera,
                        size)
    np.testing.assert_allclose(px, [[50.0, 50.0]], atol=1e-12)


@pytest.mark.parametrize("ortho", [False, True])
def test_camera_rays_pass_through_their_pixels(ortho):
    pose = Pose(scaling=0.8, translation=(20.0, 10.0, -700.0), roll=0.2, yaw=0.6, pitch=-0.3)
    view = View(translation=(5.0, -3.0, 20.0), yaw=0.05)
    camera = Camera(focal_length=7.5, sensor_size=(3.0, 2.0), near=300.0 if ortho else 10.0,
                    far=5000.0, principal_point=(0.1, 0.2), orthographic=ortho)
    size = ImageSize(30, 20)
    o, d = cam.camera_rays(camera, size, pose, view)
    assert o.shape == d.shape == (600, 3) and o.dtype == d.dtype == np.float32
    jj, ii = np.divmod(np.arange(600), 30)  # row-major: index j * W + i is pixel (i, j)
    for t in (0.0, 250.0, 1000.0):
        p = o.astype(np.float64) + t * d.astype(np.float64)
        px, depth = cam.project(p, pose, view, camera, size)
        np.testing.assert_allclose(px[:, 0], ii, atol=2e-3)
        np.testing.assert_allclose(px[:, 1], jj, atol=2e-3)
        # ray parameter t is eye depth minus near
        np.testing.assert_allclose(cam.eye_depth(depth, camera), t + camera.near, rtol=1e-4)


def test_camera_rays_out_buffers_and_cache_independence():
    camera, size, view = Camera(), ImageSize(16, 12), View()
    out = (np.empty((192, 3), np.float32), np.empty((192, 3), np.float32))
    o1, d1 = cam.camera_rays(camera, size, Pose(yaw=0.2), view, out=out)
    assert o1 is out[0] and d1 is out[1]
    o2, d2 = cam.camera_rays(camera, size, Pose(yaw=0.2), view)
    np.testing.assert_array_equal(o1, o2)
    np.testing.assert_array_equal(d1, d2)
    o3, _ = cam.camera_rays(camera._replace(focal_length=8.0), size, Pose(yaw=0.2), view)
    assert not np.array_equal(o2, o3)


def test_camera_rays_of_some_pixels_are_those_rows_of_all():
    camera, size, view, pose = Camera(), ImageSize(16, 12), View(), Pose(yaw=0.2, pitch=-0.1)
    pixels = np.array([191, 0, 17, 17, 100])  # any order, repeats allowed
    o, d = cam.camera_rays(camera, size, pose, view)
    os_, ds = cam.camera_rays(camera, size, pose, view, pixels=pixels)
    assert os_.shape == ds.shape == (5, 3)
    np.testing.assert_allclose(os_, o[pixels], rtol=1e-6, atol=1e-4)
    np.testing.assert_allclose(ds, d[pixels], rtol=1e-6, atol=1e-6)


def test_unproject_inverts_project():
    rng = np.random.default_rng(0)
    pts = rng.normal(0, 50, (20, 3))
    pose = Pose(scaling=1.1, translation=(0.0, 5.0, -600.0), roll=0.1, yaw=0.3, pitch=0.2)
    for ortho in (False, True):
        camera = Camera(principal_point=(0.05, -0.1), orthographic=ortho, near=100.0, far=2000.0)
        size = ImageSize(80, 60)
        px, depth = cam.project(pts, pose, View(), camera, size)
        back = cam.unproject(px, depth, pose, View(), camera, size)
        np.testing.assert_allclose(back, pts, atol=1e-6)


def test_eye_and_towards_camera_in_model_frame():
    pose = Pose(scaling=2.0, translation=(10.0, 20.0, -500.0), roll=0.3, yaw=-0.4, pitch=0.2)
    view = View(translation=(1.0, 2.0, 3.0), yaw=0.1)
    eye = cam.eye_position_model(pose, view)
    np.testing.assert_allclose(cam.to_eye(eye[None], pose, view), [[0, 0, 0]], atol=1e-9)
    toward = cam.towards_camera_model(pose, view)
    a = cam.to_eye(np.array([[0.0, 0.0, 0.0], toward]), pose, view)
    step = (a[1] - a[0]) / np.linalg.norm(a[1] - a[0])
    np.testing.assert_allclose(step, [0, 0, 1], atol=1e-12)
