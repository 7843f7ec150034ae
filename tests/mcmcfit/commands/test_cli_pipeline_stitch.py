"""``mcmcfit pipeline stitch`` on an analytic two-view sphere and on the AlbedoMM sample."""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.io
import trimesh

from albedo_model.io.image_io import read_image, write_png
from mcmcfit.cli import main

pytestmark = pytest.mark.embree

SIZE = (240, 200)  # h, w
FOCAL = 400.0


def _texture(p):
    return 0.45 + p @ np.array([[0.2, 0.05, -0.1], [0.0, 0.25, 0.1], [0.1, -0.05, 0.2]]).T


def _view(eye):
    """Extrinsics T (world -> camera, +z forward, y down) of a camera at ``eye`` looking at 0."""
    z = -np.asarray(eye, float) / np.linalg.norm(eye)
    y = -(np.array([0.0, 1.0, 0.0]) - z[1] * z)
    y /= np.linalg.norm(y)
    R = np.stack([np.cross(y, z), y, z])
    return np.vstack([np.hstack([R, (-R @ eye)[:, None]]), [0, 0, 0, 1]])


def _render(T, offset):
    """Exact image of the unit sphere through a distortion-free camera, 8-bit PNG values."""
    h, w = SIZE
    rows, cols = np.mgrid[0:h, 0:w]
    d_cam = np.stack([(cols - (w - 1) / 2) / FOCAL, (rows - (h - 1) / 2) / FOCAL,
                      np.ones((h, w))], -1).reshape(-1, 3)
    R, t = T[:3, :3], T[:3, 3]
    d = d_cam @ R
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    eye = -R.T @ t
    b = d @ eye
    disc = b * b - (eye @ eye - 1.0)
    hit = disc >= 0
    p = eye + (-b[hit] - np.sqrt(disc[hit]))[:, None] * d[hit]
    img = np.zeros((h * w, 3))
    img[hit] = _texture(p) + offset
    return img.reshape(h, w, 3)


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    folder = tmp_path_factory.mktemp("capture")
    sphere = trimesh.creation.icosphere(subdivisions=4)
    sphere.export(folder / "mesh.ply")
    scipy.io.savemat(folder / "mesh.mat", {"V": sphere.vertices, "F": sphere.faces + 1})
    views = []
    for i, (eye, offset) in enumerate([((0, 0, 6.0), 0.0), ((4.2, 0, 4.2), 0.1)]):
        T = _view(np.array(eye))
        write_png(folder / f"v{i}.png", _render(T, offset))
        views.append({"image": f"v{i}.png", "T": T.tolist()})
    cams = {"intrinsics": {"h": SIZE[0], "w": SIZE[1], "f": FOCAL,
                           "cx": (SIZE[1] - 1) / 2 + 1, "cy": (SIZE[0] - 1) / 2 + 1},
            "views": views,
            "stitching": {"boundary_distance_px": 6, "lambda": 0.1, "reference_view": 0}}
    (folder / "cameras.json").write_text(json.dumps(cams))
    return folder, np.asarray(sphere.vertices)


def test_stitch_two_views(capture, tmp_path, capsys):
    folder, vertices = capture
    out, png = tmp_path / "texture.npz", tmp_path / "preview.png"
    code = main(["pipeline", "stitch", str(folder / "mesh.ply"), str(folder / "v0.png"),
                 str(folder / "v1.png"), "--cameras", str(folder / "cameras.json"),
                 "-o", str(out), "--png", str(png), "--preview-scale", "1"])
    assert code == 0
    text = capsys.readouterr().out
    assert "wrote" in text and "relative residual" in text and "seconds:" in text
    with np.load(out, allow_pickle=False) as d:
        n, m = len(vertices), 20 * 4**4
        assert d["colour"].shape == (n, 3) and d["weights"].shape == (2, n)
        assert d["valid"].shape == (2, n) and d["valid"].dtype == bool
        assert d["selected_view"].shape == (m,) and d["triangles"].shape == (m, 3)
        assert d["samples"].shape == (2, n, 3)
        np.testing.assert_allclose(d["vertices"], vertices)
        assert d["views"].tolist() == ["v0.png", "v1.png"] and int(d["reference_view"]) == 0
        colour, valid, sel = d["colour"], d["valid"], d["selected_view"]
    assert set(np.unique(sel)) == {-1, 0, 1}
    # view 2 is 0.1 brighter; stitching removes the offset everywhere either view saw
    seen = valid.any(axis=0)
    np.testing.assert_allclose(colour[seen], _texture(vertices[seen]), atol=0.01)
    assert np.isfinite(colour).all()
    picture = read_image(png)
    assert picture.shape[0] >= 3 * 100 and picture.shape[1] > 2 * 100


def test_mat_mesh_gives_the_same_texture(capture, tmp_path):
    folder, _ = capture
    results = []
    for mesh in ("mesh.ply", "mesh.mat"):
        out = tmp_path / f"{mesh}.npz"
        assert main(["pipeline", "stitch", str(folder / mesh), str(folder / "v0.png"),
                     str(folder / "v1.png"), "--cameras", str(folder / "cameras.json"),
                     "-o", str(out), "--reference-view", "2", "--lambda", "0.5"]) == 0
        with np.load(out) as d:
            results.append(d["colour"])
            assert int(d["reference_view"]) == 1 and float(d["lam"]) == 0.5
    # PLY stores float32 coordinates: the geometry differs by ~3e-8
    np.testing.assert_allclose(results[0], results[1], atol=1e-5)


def test_wrong_view_count(capture, tmp_path, capsys):
    folder, _ = capture
    out = tmp_path / "t.npz"
    code = main(["pipeline", "stitch", str(folder / "mesh.ply"), str(folder / "v0.png"),
                 "--cameras", str(folder / "cameras.json"), "-o", str(out)])
    assert code == 2
    err = capsys.readouterr().err
    assert "cameras.json" in err and "2 views but 1 photographs" in err
    assert not out.exists()


def test_image_of_wrong_size(capture, tmp_path, capsys):
    folder, _ = capture
    small = tmp_path / "small.png"
    write_png(small, np.zeros((10, 10, 3)))
    code = main(["pipeline", "stitch", str(folder / "mesh.ply"), str(small),
                 str(folder / "v1.png"), "--cameras", str(folder / "cameras.json"),
                 "-o", str(tmp_path / "t.npz")])
    assert code == 2
    assert "small.png: is 10x10 pixels but its camera expects 200x240" in capsys.readouterr().err


def test_bad_mat_file(tmp_path, capture, capsys):
    folder, _ = capture
    bad = tmp_path / "bad.mat"
    scipy.io.savemat(bad, {"V": np.zeros((3, 3))})
    code = main(["pipeline", "stitch", str(bad), str(folder / "v0.png"), str(folder / "v1.png"),
                 "--cameras", str(folder / "cameras.json"), "-o", str(tmp_path / "t.npz")])
    assert code == 2 and "bad.mat: needs variables 'V'" in capsys.readouterr().err


def test_albedomm_sample(shared_data, tmp_path, capsys):
    folder = shared_data / "albedomm_sample"
    out, png = tmp_path / "texture.npz", tmp_path / "preview.png"
    code = main(["pipeline", "stitch", str(folder / "FV.mat")]
                + [str(folder / f"im{i}.jpg") for i in (1, 2, 3)]
                + ["--cameras", str(folder / "cameras.json"), "-o", str(out), "--png", str(png),
                   "--preview-scale", "8"])
    assert code == 0
    assert "53149 vertices, 3 views, reference view 1, lambda 0.1" in capsys.readouterr().out
    with np.load(out) as d:
        assert d["colour"].shape == (53149, 3) and np.isfinite(d["colour"]).all()
        assert d["selected_view"].shape == (105694,)
        assert float(d["boundary_distance_px"]) == 100.0
    assert read_image(png).shape[1] > 500
