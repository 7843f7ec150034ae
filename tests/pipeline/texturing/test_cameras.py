"""Lightstage camera: distortion formula, inversion, rays, scaling, camera files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from albedo_model.errors import FormatError, InputError
from pipeline.texturing.cameras import LightstageCamera, load_cameras, rig_from_dict

K = {"k1": -0.2, "k2": 0.5, "k3": -1.5, "p1": 0.004, "p2": -0.007}  # OpenCV meaning of p1, p2


def _camera(**kw) -> LightstageCamera:
    c, s = np.cos(0.3), np.sin(0.3)
    R = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    args = {"rotation": R, "translation": np.array([0.1, -0.2, 4.0]), "focal_px": 1000.0,
            "principal_px": np.array([310.0, 250.0]), "image_size": (480, 640),
            "distortion": np.array([K[k] for k in ("k1", "k2", "k3", "p1", "p2")])}
    args.update(kw)
    return LightstageCamera(**args)


def test_projection_matches_hand_computation():
    cam = _camera()
    X = np.array([[0.3, -0.25, 0.4]])
    Xc = cam.rotation @ X[0] + cam.translation
    x, y = Xc[0] / Xc[2], Xc[1] / Xc[2]
    r2 = x * x + y * y
    radial = 1 + K["k1"] * r2 + K["k2"] * r2**2 + K["k3"] * r2**3
    # OpenCV (calib3d docs): x'' = x' radial + 2 p1 x' y' + p2 (r^2 + 2 x'^2), likewise y''
    xd = x * radial + 2 * K["p1"] * x * y + K["p2"] * (r2 + 2 * x * x)
    yd = y * radial + K["p1"] * (r2 + 2 * y * y) + 2 * K["p2"] * x * y
    expected = [310.0 + 1000.0 * xd, 250.0 + 1000.0 * yd]
    np.testing.assert_allclose(cam.project(X)[0], expected, rtol=0, atol=1e-9)


def test_projection_of_known_numbers():
    # camera at the origin looking down +z, x = 0.1, y = 0.2 by construction
    cam = _camera(rotation=np.eye(3), translation=np.zeros(3))
    uv = cam.project(np.array([[0.2, 0.4, 2.0]]))[0]
    # r2 = 0.05; radial = 1 - 0.01 + 0.00125 - 0.0001875 = 0.9910625
    # xd = 0.09910625 + 2*0.004*0.02 + (-0.007)*(0.05 + 0.02) = 0.09877625
    # yd = 0.1982125 + 0.004*(0.05 + 0.08) + 2*(-0.007)*0.02 = 0.1984525
    np.testing.assert_allclose(uv, [310.0 + 98.77625, 250.0 + 198.4525], atol=1e-9)


def test_camera_validates_its_arrays():
    with pytest.raises(InputError, match="rotation"):
        _camera(rotation=np.eye(2))
    with pytest.raises(InputError, match="focal length"):
        _camera(focal_px=0.0)
    cam = _camera()
    with pytest.raises(ValueError):
        cam.distortion[0] = 1.0  # read-only


def test_point_behind_camera_is_nan():
    cam = _camera(rotation=np.eye(3), translation=np.zeros(3))
    uv = cam.project(np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 1.0]]))
    assert np.isnan(uv[0]).all() and np.allclose(uv[1], [310.0, 250.0])


def test_undistort_inverts_distort():
    cam = _camera()
    rng = np.random.default_rng(3)
    xy = rng.uniform(-0.3, 0.3, (500, 2))
    back, ok = cam.undistort(cam.distort(xy))
    assert ok.all()
    np.testing.assert_allclose(back, xy, atol=1e-10)


def test_undistort_reports_folded_field():
    # strong negative k3: beyond r ~ 0.4 the distortion folds over and cannot be inverted
    cam = _camera(distortion=np.array([0.0, 0.0, -20.0, 0.0, 0.0]))
    _, ok = cam.undistort(np.array([[0.05, 0.0], [2.0, 0.0]]))
    assert ok.tolist() == [True, False]


def test_pixel_rays_round_trip_and_centre():
    cam = _camera()
    rng = np.random.default_rng(4)
    uv = rng.uniform([0, 0], [639, 479], (300, 2))
    dirs, ok = cam.pixel_rays(uv)
    assert ok.all()
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1.0)
    depth = rng.uniform(1.0, 9.0, (300, 1))
    points = cam.centre + depth * dirs
    np.testing.assert_allclose(cam.project(points), uv, atol=1e-7)
    np.testing.assert_allclose(cam.to_camera(cam.centre[None])[0], 0.0, atol=1e-12)


def test_scaled_camera_keeps_pixel_centres():
    cam = _camera()
    small = cam.scaled(4)
    X = np.array([[0.3, -0.25, 0.4], [-0.2, 0.1, 0.0]])
    np.testing.assert_allclose(small.project(X), (cam.project(X) + 0.5) / 4 - 0.5, atol=1e-9)
    assert small.image_size == (120, 160)


def _sample_file_dict() -> dict:
    return {
        "intrinsics": {"h": 480, "w": 640, "f": 1000.0, "cx": 311.0, "cy": 251.0,
                       "k1": -0.2, "k2": 0.5, "k3": -1.5, "p1": -0.007, "p2": 0.004},
        "views": [{"image": "a.jpg", "T": [[1, 0, 0, 0.1], [0, 1, 0, 0], [0, 0, 1, 4],
                                           [0, 0, 0, 1]]},
                  {"image": "b.jpg", "T": [[0, 0, 1, 0], [0, 1, 0, 0], [-1, 0, 0, 4]],
                   "intrinsics": {"f": 1200.0}}],
        "stitching": {"boundary_distance_px": 50, "lambda": 0.5, "reference_view": 1},
    }


def test_rig_from_dict_matlabrenderer_convention():
    rig = rig_from_dict(_sample_file_dict())
    a, b = rig.cameras
    # 1-based principal point -> 0-based; MatlabRenderer p1/p2 are OpenCV's p2/p1
    np.testing.assert_allclose(a.principal_px, [310.0, 250.0])
    np.testing.assert_allclose(a.distortion, [-0.2, 0.5, -1.5, 0.004, -0.007])
    assert b.focal_px == 1200.0 and a.focal_px == 1000.0
    assert rig.images == ("a.jpg", "b.jpg")
    assert (rig.settings.boundary_distance_px, rig.settings.lam, rig.settings.reference_view) \
        == (50.0, 0.5, 1)
    # the convention stated in the sample's cameras.json, in 1-based pixels
    X = np.array([[0.2, -0.3, 1.0]])
    Xc = X[0] + [0.1, 0, 4]
    x, y = Xc[0] / Xc[2], Xc[1] / Xc[2]
    r2 = x * x + y * y
    rad = 1 - 0.2 * r2 + 0.5 * r2**2 - 1.5 * r2**3
    p1, p2 = -0.007, 0.004  # as written in the file
    xd = x * rad + p1 * (r2 + 2 * x * x) + 2 * p2 * x * y
    yd = y * rad + p2 * (r2 + 2 * y * y) + 2 * p1 * x * y
    np.testing.assert_allclose(a.project(X)[0] + 1, [311 + 1000 * xd, 251 + 1000 * yd], atol=1e-9)


def test_rig_from_dict_opencv_convention():
    d = _sample_file_dict()
    d["intrinsics"].update(tangential="opencv", pixel_origin=0)
    a = rig_from_dict(d).cameras[0]
    np.testing.assert_allclose(a.principal_px, [311.0, 251.0])
    np.testing.assert_allclose(a.distortion, [-0.2, 0.5, -1.5, -0.007, 0.004])


@pytest.mark.parametrize("edit, message", [
    (lambda d: d["views"][0].pop("T"), r"views\[0\]: missing 'T'"),
    (lambda d: d["views"][0].update(T=[[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]]),
     "not a proper rotation"),
    (lambda d: d["intrinsics"].pop("f"), "missing 'f'"),
    (lambda d: d["stitching"].update(reference_view=2), "reference_view 2"),
    (lambda d: d.update(views=[]), "non-empty 'views'"),
])
def test_malformed_camera_files(tmp_path, edit, message):
    d = _sample_file_dict()
    edit(d)
    path = tmp_path / "cams.json"
    path.write_text(json.dumps(d))
    with pytest.raises(FormatError, match=message) as info:
        load_cameras(path)
    assert str(path) in str(info.value)
    with pytest.raises(InputError, match=message):
        rig_from_dict(d)


def test_not_json_and_missing(tmp_path):
    bad = tmp_path / "cams.json"
    bad.write_text("{nope")
    with pytest.raises(FormatError, match="not a JSON file"):
        load_cameras(bad)
    with pytest.raises(InputError, match="file not found"):
        load_cameras(tmp_path / "absent.json")


def test_albedomm_sample_cameras(shared_data):
    rig = load_cameras(shared_data / "albedomm_sample" / "cameras.json")
    assert len(rig.cameras) == 3 and rig.images == ("im1.jpg", "im2.jpg", "im3.jpg")
    s = rig.settings
    assert (s.boundary_distance_px, s.lam, s.reference_view) == (100.0, 0.1, 0)
    cam = rig.cameras[0]
    assert cam.image_size == (3872, 2592)
    np.testing.assert_allclose(cam.principal_px, [1322.7, 2401.0])
    # camera centre: -R^T t of the published extrinsics
    T = np.array(json.loads((shared_data / "albedomm_sample" / "cameras.json").read_text())
                 ["views"][0]["T"])
    np.testing.assert_allclose(cam.centre, -T[:3, :3].T @ T[:3, 3])
