"""Coloured mesh export (PLY, OBJ), read back with trimesh."""

from __future__ import annotations

import numpy as np
import pytest

from albedo_model.errors import FormatError, InputError
from albedo_model.io.mesh_export import colours_to_uint8, write_mesh

trimesh = pytest.importorskip("trimesh")


@pytest.fixture(scope="module")
def sphere():
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=90.0)
    return np.asarray(mesh.vertices), np.asarray(mesh.faces, np.int32)


def load(path):
    mesh = trimesh.load(path, process=False)
    assert isinstance(mesh, trimesh.Trimesh)
    return mesh


@pytest.mark.parametrize("suffix", [".ply", ".obj", ".PLY"])
def test_linear_float_colours_round_trip(tmp_path, sphere, suffix):
    verts, tris = sphere
    rng = np.random.default_rng(3)
    colours = rng.uniform(0.0, 1.0, (len(verts), 3))
    path = tmp_path / f"mesh{suffix}"
    write_mesh(path, verts, tris, colours)
    mesh = load(path)
    assert len(mesh.vertices) == len(verts) == 162
    np.testing.assert_array_equal(mesh.faces, tris)
    np.testing.assert_allclose(mesh.vertices, verts, rtol=0, atol=1e-4)  # float32 / 8 digits
    expected = np.floor(colours * 255 + 0.5).astype(np.uint8)  # linear values, 8 bit
    np.testing.assert_array_equal(mesh.visual.vertex_colors[:, :3], expected)
    assert np.all(mesh.visual.vertex_colors[:, 3] == 255)


def test_gamma_encoding_and_clipping(tmp_path, sphere):
    verts, tris = sphere
    colours = np.full((len(verts), 3), 0.5)
    colours[0] = [-0.3, 1.7, 0.0]  # renderer output is not clamped
    colours[1] = [1.0, 0.25, 1e-3]
    path = tmp_path / "g.ply"
    write_mesh(path, verts, tris, colours, gamma=2.2)
    got = load(path).visual.vertex_colors[:, :3]
    assert tuple(got[0]) == (0, 255, 0)
    assert tuple(got[1]) == (255, round(255 * 0.25 ** (1 / 2.2)), round(255 * 1e-3 ** (1 / 2.2)))
    assert tuple(got[2]) == (186, 186, 186)  # 255 * 0.5 ** (1 / 2.2) = 186.08


def test_uint8_colours_are_written_unchanged(tmp_path, sphere):
    verts, tris = sphere
    colours = np.random.default_rng(0).integers(0, 256, (len(verts), 3)).astype(np.uint8)
    for suffix in (".ply", ".obj"):
        write_mesh(tmp_path / f"u{suffix}", verts, tris, colours)
        np.testing.assert_array_equal(load(tmp_path / f"u{suffix}").visual.vertex_colors[:, :3],
                                      colours)
    with pytest.raises(InputError, match="gamma"):
        colours_to_uint8(colours, gamma=2.2)


def test_mesh_without_colours(tmp_path, sphere):
    verts, tris = sphere
    write_mesh(tmp_path / "plain.ply", verts, tris)
    mesh = load(tmp_path / "plain.ply")
    assert len(mesh.vertices) == len(verts) and len(mesh.faces) == len(tris)


@pytest.mark.parametrize("make_args,error,reason", [
    (lambda v, t: ("m.stl", v, t, None), FormatError, "unsupported mesh format"),
    (lambda v, t: ("m.ply", v, t, np.zeros((3, 3))), InputError, "colours for"),
    (lambda v, t: ("m.ply", v, t + len(v), None), InputError, "triangle indices"),
    (lambda v, t: ("m.ply", v[:, :2], t, None), InputError, "vertices must have shape"),
    (lambda v, t: ("m.obj", v, t.astype(float), None), InputError, "integer"),
    (lambda v, t: ("m.ply", v, t, np.full((len(v), 3), np.nan)), InputError, "NaN"),
    (lambda v, t: ("m.ply", v, t, np.zeros((len(v), 4))), InputError, r"\(n, 3\)"),
])
def test_bad_input_writes_nothing(tmp_path, sphere, make_args, error, reason):
    verts, tris = sphere
    name, v, t, c = make_args(verts, tris)
    existing = tmp_path / "m.ply"
    existing.write_bytes(b"keep")
    with pytest.raises(error, match=reason):
        write_mesh(tmp_path / name, v, t, c)
    assert existing.read_bytes() == b"keep"
    assert {p.name for p in tmp_path.iterdir()} == {"m.ply"}
