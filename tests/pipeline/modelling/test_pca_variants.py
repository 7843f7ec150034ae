"""Albedo PCA variants against brute-force definitions; symmetry augmentation; determinism."""

import numpy as np
import pytest

from albedo_model.errors import InputError
from pipeline.modelling.pca_variants import (
    VARIANTS, augment_with_mirror, build_albedo_parts, mirror_maps,
)
from pipeline.synthetic.subjects import make_subjects

N_VERT = 12


def _toy(rng, n_sub=6, n_vert=N_VERT):
    """Random maps on a toy 'mesh' whose symmetry swaps vertex pairs (0,1), (2,3), ... ."""
    sym = np.arange(n_vert) ^ 1
    diffuse = rng.uniform(0.1, 0.6, (n_sub, n_vert, 3))
    specular = 0.2 + 0.3 * diffuse[..., :1] * rng.uniform(0.5, 1.5, (n_sub, n_vert, 1)) \
        + rng.normal(0, 0.02, (n_sub, n_vert, 3))
    return diffuse, specular, sym


def _cov_eig(x):
    """Eigenvalues (descending) and eigenvectors of the sample covariance, brute force."""
    lam, vec = np.linalg.eigh(np.cov(x, rowvar=False))
    return lam[::-1], vec[:, ::-1]


def _residual(part_scaled_basis, mean, x):
    c, *_ = np.linalg.lstsq(part_scaled_basis, x - mean, rcond=None)
    return np.linalg.norm(x - mean - part_scaled_basis @ c) / np.linalg.norm(x - mean)


def test_augmentation_appends_mirrored_copies():
    d, _, sym = _toy(np.random.default_rng(0))
    aug = augment_with_mirror(d, sym)
    assert aug.shape == (2 * len(d), N_VERT, 3)
    np.testing.assert_array_equal(aug[: len(d)], d)
    np.testing.assert_array_equal(aug[len(d):, 0], d[:, 1])
    np.testing.assert_array_equal(mirror_maps(mirror_maps(d, sym), sym), d)


def test_independent_equals_covariance_eigendecomposition():
    d, s, sym = _toy(np.random.default_rng(1))
    parts = build_albedo_parts(d, s, sym, variant="independent")
    assert not parts.shared
    for part, data in ((parts.diffuse, d), (parts.specular, s)):
        x = augment_with_mirror(data, sym).reshape(2 * len(data), -1)
        lam, vec = _cov_eig(x)
        k = part.rank
        np.testing.assert_allclose(part.variance, lam[:k], rtol=1e-8)
        np.testing.assert_allclose(np.abs(part.basis.T @ vec[:, :k]), np.eye(k), atol=1e-6)
        np.testing.assert_allclose(part.mean, x.mean(0))


def test_concatenated_equals_joint_pca_split_in_two():
    d, s, sym = _toy(np.random.default_rng(2))
    parts = build_albedo_parts(d, s, sym, variant="concatenated")
    assert parts.shared and parts.diffuse.rank == parts.specular.rank
    x = np.hstack([augment_with_mirror(a, sym).reshape(2 * len(a), -1) for a in (d, s)])
    lam, vec = _cov_eig(x)
    k = parts.diffuse.rank
    c = np.random.default_rng(3).standard_normal(k)
    stacked = np.vstack([parts.diffuse.scaled_basis, parts.specular.scaled_basis])
    signs = np.sign(np.sum(vec[:, :k] * stacked, 0))
    joint = x.mean(0) + vec[:, :k] @ (signs * np.sqrt(lam[:k]) * c)
    dim = 3 * N_VERT
    np.testing.assert_allclose(parts.diffuse.instance(c), joint[:dim], atol=1e-9)
    np.testing.assert_allclose(parts.specular.instance(c), joint[dim:], atol=1e-9)
    gram = parts.diffuse.basis.T @ parts.diffuse.basis
    np.testing.assert_allclose(np.diag(gram), 1.0)
    assert np.abs(gram - np.eye(k)).max() > 1e-3  # the paper's point: blocks are not orthonormal


def test_transferred_shares_diffuse_coefficients():
    d, s, sym = _toy(np.random.default_rng(4))
    parts = build_albedo_parts(d, s, sym, variant="transferred")
    indep = build_albedo_parts(d, s, sym, variant="independent")
    assert parts.shared and parts.specular.rank == parts.diffuse.rank
    np.testing.assert_allclose(parts.diffuse.variance, indep.diffuse.variance)
    overlap = np.abs(parts.diffuse.basis.T @ indep.diffuse.basis)
    np.testing.assert_allclose(overlap, np.eye(parts.diffuse.rank), atol=1e-8)
    xd = augment_with_mirror(d, sym).reshape(2 * len(d), -1)
    xs = augment_with_mirror(s, sym).reshape(2 * len(s), -1)
    # full rank: a training sample's diffuse coefficients reproduce its specular map
    coeffs = parts.diffuse.project(xd, regularization=0.0)
    for i in range(len(xd)):
        np.testing.assert_allclose(parts.specular.instance(coeffs[i]), xs[i], atol=1e-9)
    # implied specular covariance is the sample covariance
    implied = parts.specular.scaled_basis @ parts.specular.scaled_basis.T
    np.testing.assert_allclose(implied, np.cov(xs, rowvar=False), atol=1e-10)
    # truncated: specular modes = least-squares regression of specular on diffuse coefficients
    small = build_albedo_parts(d, s, sym, variant="transferred", rank=3)
    c3 = small.diffuse.project(xd, regularization=0.0)
    reg, *_ = np.linalg.lstsq(c3, xs - xs.mean(0), rcond=None)
    np.testing.assert_allclose(small.specular.scaled_basis, reg.T, atol=1e-10)


@pytest.mark.parametrize("variant", VARIANTS)
@pytest.mark.parametrize("rank", [None, 4])
def test_mirrored_model_sample_stays_in_model(variant, rank):
    d, s, sym = _toy(np.random.default_rng(5))
    parts = build_albedo_parts(d, s, sym, variant=variant, rank=rank)
    rng = np.random.default_rng(6)
    for part in (parts.diffuse, parts.specular):
        x = part.sample(rng).reshape(N_VERT, 3)
        mirrored = mirror_maps(x, sym).reshape(-1)
        assert _residual(part.scaled_basis, part.mean, mirrored) < 1e-8
        mean_mirrored = mirror_maps(part.mean.reshape(N_VERT, 3), sym).reshape(-1)
        np.testing.assert_allclose(mean_mirrored, part.mean)
    if parts.shared:  # one coefficient vector: the mirrored pair is explained by one vector too
        c = rng.standard_normal(parts.diffuse.rank)
        pair = np.concatenate([mirror_maps(p.instance(c).reshape(N_VERT, 3), sym).reshape(-1)
                               for p in (parts.diffuse, parts.specular)])
        joint = np.vstack([parts.diffuse.scaled_basis, parts.specular.scaled_basis])
        mean = np.concatenate([parts.diffuse.mean, parts.specular.mean])
        assert _residual(joint, mean, pair) < 1e-8


def test_without_augmentation_mirror_is_not_in_span():
    d, s, sym = _toy(np.random.default_rng(7))
    part = build_albedo_parts(d, s, None, variant="independent").diffuse
    x = mirror_maps(d[0], sym).reshape(-1)
    assert _residual(part.scaled_basis, part.mean, x) > 1e-3


def test_rebuilding_from_same_seed_reproduces_model(stand_in_head):
    def build():
        subs = make_subjects(stand_in_head, 5, seed=11)
        return build_albedo_parts(
            np.stack([x.diffuse for x in subs]), np.stack([x.specular for x in subs]),
            stand_in_head.symmetry, variant="transferred",
        )

    a, b = build(), build()
    for pa, pb in zip(a[:2], b[:2]):
        np.testing.assert_array_equal(pa.mean, pb.mean)
        np.testing.assert_array_equal(pa.basis, pb.basis)
        np.testing.assert_array_equal(pa.variance, pb.variance)
    assert a.diffuse.rank == 9  # 10 augmented samples


def test_bad_input_raises():
    d, s, sym = _toy(np.random.default_rng(8))
    with pytest.raises(InputError, match="differ in shape"):
        build_albedo_parts(d, s[:, :-2], sym)
    with pytest.raises(InputError, match="involution"):
        build_albedo_parts(d, s, np.roll(sym, 1))
    with pytest.raises(InputError, match="variant"):
        build_albedo_parts(d, s, sym, variant="joint")
    with pytest.raises(InputError, match="shape"):
        build_albedo_parts(d[..., :2], s[..., :2], sym)
