"""Shape (GP) and expression PCA parts on the template head."""

from __future__ import annotations

import numpy as np
import pytest

from albedo_model.errors import InputError
from pipeline.synthetic.head.shape_model import (
    EXPRESSION_MODES,
    _kernel,
    build_expression_model,
    build_shape_model,
)
from pipeline.modelling.symmetry import mirror_flat
from pipeline.synthetic.head.template_head import TemplateHead, build_template_head


@pytest.fixture(scope="module")
def head() -> TemplateHead:
    return build_template_head()


@pytest.fixture(scope="module")
def shape(head):
    return build_shape_model(head, rank=40, seed=0)


@pytest.fixture(scope="module")
def expression(head):
    return build_expression_model(head)


def test_shape_part_layout(head, shape) -> None:
    n = head.n_vertices
    assert shape.dim == 3 * n and shape.rank == 40
    np.testing.assert_array_equal(shape.mean, head.vertices.reshape(-1))
    np.testing.assert_allclose(shape.basis.T @ shape.basis, np.eye(40), atol=1e-9)
    assert np.all(np.diff(shape.variance) <= 0) and shape.variance[-1] > 0


def test_every_mode_is_symmetric_or_antisymmetric(head, shape) -> None:
    parity = np.einsum("ij,ij->j", mirror_flat(shape.basis, head.symmetry), shape.basis)
    np.testing.assert_allclose(np.abs(parity), 1.0, atol=1e-9)
    assert (parity > 0).sum() > 20 and (parity < 0).sum() >= 1


def test_mirrored_sample_stays_in_the_model(head, shape) -> None:
    rng = np.random.default_rng(5)
    for _ in range(3):
        x = shape.sample(rng)
        mirrored = mirror_flat(x.reshape(-1, 3), head.symmetry).reshape(-1)
        back = shape.instance(shape.project(mirrored))
        assert np.abs(back - mirrored).max() < 1e-8
        # and it is a different shape (the model is not purely symmetric)
    c = np.zeros(shape.rank)
    anti = int(
        np.flatnonzero(
            np.einsum("ij,ij->j", mirror_flat(shape.basis, head.symmetry), shape.basis) < 0
        )[0]
    )
    c[anti] = 2.0
    x = shape.instance(c)
    assert np.abs(mirror_flat(x.reshape(-1, 3), head.symmetry).reshape(-1) - x).max() > 0.5


def test_rigid_motions_are_projected_out(head, shape) -> None:
    v = head.vertices
    n = len(v)
    c = v.mean(0)
    r = v - c
    zero, one = np.zeros(n), np.ones(n)
    fields = [
        (one, zero, zero), (zero, one, zero), (zero, zero, one),
        (zero, -r[:, 2], r[:, 1]), (r[:, 2], zero, -r[:, 0]), (-r[:, 1], r[:, 0], zero),
    ]  # fmt: skip
    for f in fields:
        u = np.column_stack(f).ravel()
        u /= np.linalg.norm(u)
        assert np.abs(u @ shape.basis).max() < 1e-8


def test_total_variance_is_bounded_by_the_kernel(head, shape) -> None:
    """The model's total variance is at most the trace of the kernel.

    Nyström, the down-weighted antisymmetric part, projections and truncation
    only remove variance.
    """
    v = head.vertices
    trace = sum(np.trace(_kernel(v[i : i + 500], v[i : i + 500])) for i in range(0, len(v), 500))
    total = shape.variance.sum()
    assert total <= 3.0 * trace
    assert total > 0.3 * 3.0 * trace  # rank 40 keeps most of it (smooth kernel)
    assert np.isclose(total, (shape.marginal_std() ** 2).sum())


def test_anthropometric_spread(head, shape) -> None:
    """Sizes vary by a few millimetres, as in adult populations."""
    rng = np.random.default_rng(3)
    x = shape.sample(rng, 400).reshape(400, -1, 3)
    lm = head.landmarks

    def sd(a: str, b: str) -> float:
        return float(np.linalg.norm(x[:, lm[a]] - x[:, lm[b]], axis=1).std())

    assert 3.0 < sd("center.front.trichion", "center.chin.tip") < 10.0
    assert 1.0 < sd("left.nose.wing.outer", "right.nose.wing.outer") < 4.5
    assert 1.5 < sd("left.eye.pupil.center", "right.eye.pupil.center") < 6.0
    median = np.median(np.linalg.norm(shape.marginal_std().reshape(-1, 3), axis=1))
    assert 2.0 < median < 8.0


def test_seeded_rebuild(head, shape) -> None:
    again = build_shape_model(head, rank=40, seed=0)
    np.testing.assert_array_equal(again.basis, shape.basis)
    np.testing.assert_array_equal(again.variance, shape.variance)
    other = build_shape_model(head, rank=10, seed=1)
    # another choice of inducing points changes little in the leading variances
    np.testing.assert_allclose(other.variance[:4], shape.variance[:4], rtol=0.1)


def test_rank_is_validated(head) -> None:
    with pytest.raises(InputError):
        build_shape_model(head, rank=0)


# -- expressions -------------------------------------------------------------------------
def test_expression_part_layout(head, expression) -> None:
    assert expression.rank == len(EXPRESSION_MODES) == 3
    np.testing.assert_array_equal(expression.mean, np.zeros(3 * head.n_vertices))
    np.testing.assert_allclose(expression.basis.T @ expression.basis, np.eye(3), atol=1e-12)
    assert np.all(expression.variance > 0)
    mirrored = mirror_flat(expression.basis, head.symmetry)
    np.testing.assert_allclose(mirrored, expression.basis, atol=1e-12)


def test_expression_modes_move_the_right_parts(head, expression) -> None:
    lm = head.landmarks

    def disp(mode: str, name: str) -> np.ndarray:
        c = np.zeros(3)
        c[EXPRESSION_MODES.index(mode)] = 1.0
        return expression.instance(c).reshape(-1, 3)[lm[name]]

    chin = disp("jaw_open", "center.chin.tip")
    assert chin[1] < -8.0 and chin[2] < 0.0  # the chin drops and swings back
    assert np.linalg.norm(disp("jaw_open", "center.lips.upper.outer")) < 1.0
    assert np.linalg.norm(disp("jaw_open", "center.lips.lower.outer")) > 6.0
    assert np.linalg.norm(disp("jaw_open", "center.nose.tip")) < 1e-3
    corner = disp("smile", "left.lips.corner")
    assert corner[1] > 1.0 and corner[0] > 0.5
    assert disp("brow_raise", "left.eyebrow.bend.upper")[1] > 2.0
    assert np.linalg.norm(disp("brow_raise", "left.eye.pupil.center")) < 1e-3


def test_open_jaw_does_not_fold_the_mesh(head, expression) -> None:
    t = head.triangles
    v0 = head.vertices
    v1 = v0 + expression.instance(np.array([3.0, 0.0, 0.0])).reshape(-1, 3)

    def normals(v: np.ndarray) -> np.ndarray:
        n = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
        return n / np.linalg.norm(n, axis=1, keepdims=True)

    flipped = np.einsum("ij,ij->i", normals(v0), normals(v1)) < 0.0
    assert flipped.sum() == 0
