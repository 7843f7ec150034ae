"""MorphableModel instances, normals and validation."""

import numpy as np
import pytest
import trimesh

from albedo_model.errors import InputError
from albedo_model.model import ModelCoefficients, MorphableModel, vertex_normals
from albedo_model.pca import PCAPart


def sphere_model(k=3, seed=0, specular=True):
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=50.0)
    v = np.asarray(mesh.vertices)
    n3 = 3 * len(v)
    rng = np.random.default_rng(seed)

    def part(mean):
        q, _ = np.linalg.qr(rng.standard_normal((n3, k)))
        return PCAPart(mean, q, np.arange(k, 0, -1.0))

    return MorphableModel(
        v, np.asarray(mesh.faces), part(v.ravel()), part(np.full(n3, 0.5)),
        expression=part(np.zeros(n3)), specular=part(np.full(n3, 0.2)) if specular else None,
        landmarks={"center.nose.tip": v[0], "off.mesh": v[0] + 10.0},
    )


def test_vertex_normals_of_a_sphere_point_outwards():
    m = sphere_model()
    n = vertex_normals(m.vertices, m.triangles)
    radial = m.vertices / np.linalg.norm(m.vertices, axis=1, keepdims=True)
    assert np.all(np.einsum("ij,ij->i", n, radial) > 0.99)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)


def test_vertex_normals_degenerate_mesh_has_no_nan():
    v = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [5, 5, 5.0]])
    t = np.array([[0, 1, 2], [0, 0, 1]])
    n = vertex_normals(v, t)
    assert np.all(np.isfinite(n))
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0)


def test_instance_and_shared_specular_coefficients():
    m = sphere_model()
    c = ModelCoefficients(np.array([1.0, 0, 0]), np.array([0, 2.0]), np.array([0.5, -1.0, 0]))
    inst = m.instance(c)
    np.testing.assert_allclose(
        inst["vertices"].ravel(), m.shape.instance(c.shape) + m.expression.instance(c.expression)
    )
    np.testing.assert_allclose(inst["diffuse"].ravel(), m.diffuse.instance(c.albedo))
    np.testing.assert_allclose(inst["specular"].ravel(), m.specular.instance(c.albedo))
    zero = m.instance(ModelCoefficients.zeros(m))
    np.testing.assert_allclose(zero["vertices"], m.vertices, atol=1e-12)


def test_landmark_resolution_exact_match_only():
    m = sphere_model()
    assert m.landmark_vertices == {"center.nose.tip": 0}


def test_truncate_keeps_shared_ranks_equal():
    m = sphere_model().truncate(diffuse=2, shape=1)
    assert m.ranks == {"shape": 1, "expression": 3, "diffuse": 2, "specular": 2}


def test_validation_errors():
    m = sphere_model()
    with pytest.raises(InputError, match="dimension"):
        MorphableModel(m.vertices[:-1], m.triangles[:10], m.shape, m.diffuse)
    with pytest.raises(InputError, match="equal ranks"):
        MorphableModel(m.vertices, m.triangles, m.shape, m.diffuse, specular=m.specular.truncate(1))
    with pytest.raises(InputError, match="out of range"):
        MorphableModel(m.vertices, m.triangles + len(m.vertices), m.shape, m.diffuse)
