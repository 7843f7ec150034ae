"""Leave-one-out residual variance: the Gram-space computation against an explicit rebuild."""

import numpy as np
import pytest

from albedo_model.errors import InputError
from pipeline.modelling.pca_variants import VARIANTS, build_albedo_parts, mirror_maps
from pipeline.modelling.residual_variance import (
    attach_residual_variance,
    loo_residual_variance,
    residual_rms_per_channel,
)


def _population(seed, n_sub=6, n_vert=12):
    """Faces = a few shared modes + independent per-vertex texture (out of every span)."""
    rng = np.random.default_rng(seed)
    sym = np.arange(n_vert) ^ 1
    modes = rng.normal(0, 0.05, (3, n_vert, 3))
    z = rng.standard_normal((n_sub, 3))
    diffuse = 0.4 + np.einsum("sk,kvc->svc", z, modes) + rng.normal(0, 0.02, (n_sub, n_vert, 3))
    specular = 0.1 + 0.4 * diffuse[..., 1:2] + rng.normal(0, 0.01, (n_sub, n_vert, 3))
    return diffuse, specular, sym


def _fit(scaled, y):
    return np.linalg.lstsq(scaled, y, rcond=None)[0] if scaled.shape[1] else np.zeros(0)


def _brute_force(diffuse, specular, sym, variant, rank):
    """Build each split's model explicitly, fit the held-out subject (and mirror), average r^2."""
    n_sub = len(diffuse)
    sq_d, sq_s = [], []
    for i in range(n_sub):
        keep = np.arange(n_sub) != i
        p = build_albedo_parts(diffuse[keep], specular[keep], sym, variant=variant, rank=rank)
        held = [(diffuse[i], specular[i])]
        if sym is not None:
            held.append((mirror_maps(diffuse[i], sym), mirror_maps(specular[i], sym)))
        for d, s in held:
            yd = d.reshape(-1) - p.diffuse.mean
            ys = s.reshape(-1) - p.specular.mean
            c = _fit(p.diffuse.scaled_basis, yd)
            sq_d.append((yd - p.diffuse.scaled_basis @ c) ** 2)
            cs = c if p.shared else _fit(p.specular.scaled_basis, ys)
            sq_s.append((ys - p.specular.scaled_basis @ cs) ** 2)
    return np.mean(sq_d, axis=0), np.mean(sq_s, axis=0)


@pytest.mark.parametrize("variant", VARIANTS)
@pytest.mark.parametrize("augment", [True, False])
@pytest.mark.parametrize("rank", [None, 3])
def test_gram_computation_equals_explicit_rebuild(variant, augment, rank):
    for seed in range(3):
        d, s, sym = _population(seed)
        sym = sym if augment else None
        res = loo_residual_variance(d, s, sym, variant=variant, rank=rank)
        ref_d, ref_s = _brute_force(d, s, sym, variant, rank)
        scale = ref_d.mean()
        np.testing.assert_allclose(res.diffuse, ref_d, rtol=1e-7, atol=1e-10 * scale)
        np.testing.assert_allclose(res.specular, ref_s, rtol=1e-7, atol=1e-10 * scale)
        assert res.n_held_out == len(d) * (2 if augment else 1)
        full = (len(d) - 1) * (2 if augment else 1) - 1
        assert res.rank == (full if rank is None else rank)


def test_colour_only_model_and_symmetric_estimate():
    d, s, sym = _population(4)
    res = loo_residual_variance(d, None, sym)
    assert res.specular is None
    ref, _ = _brute_force(d, s, sym, "independent", None)
    np.testing.assert_allclose(res.diffuse, ref, rtol=1e-7)
    # both copies are scored: the per-vertex estimate is mirror symmetric
    per_vertex = res.diffuse.reshape(-1, 3)
    np.testing.assert_allclose(per_vertex, per_vertex[sym], rtol=1e-9)


def test_out_of_span_noise_variance_is_recovered():
    """Faces in a 2-D span plus iid noise sigma^2: LOO at rank 2 gives ~sigma^2 (1 + 2/S)."""
    rng = np.random.default_rng(7)
    n_sub, n_vert, sigma = 40, 200, 0.02
    modes = rng.normal(0, 0.1, (2, n_vert, 3))
    d = 0.4 + np.einsum("sk,kvc->svc", rng.standard_normal((n_sub, 2)), modes)
    d = d + rng.normal(0, sigma, d.shape)
    res = loo_residual_variance(d, None, None, rank=2)
    # held-out residual: noise + estimation error of mean and span, a few % above sigma^2
    ratio = res.diffuse.mean() / sigma**2
    assert 1.0 < ratio < 1.2
    assert residual_rms_per_channel(res.diffuse) == pytest.approx(sigma * np.sqrt(ratio), rel=0.1)
    # the in-sample residual at the same rank is smaller: LOO is the honest one
    parts = build_albedo_parts(d, d, None, variant="independent", rank=2)
    x = d.reshape(n_sub, -1)
    fitted = parts.diffuse.instance(np.zeros(2)) + (
        parts.diffuse.project(x, regularization=0.0) @ parts.diffuse.scaled_basis.T)
    assert np.mean((x - fitted) ** 2) < res.diffuse.mean()


def test_attached_to_the_parts():
    d, s, sym = _population(1)
    parts = build_albedo_parts(d, s, sym, rank=4)
    res = loo_residual_variance(d, s, sym, rank=4)
    out = attach_residual_variance(parts, res)
    np.testing.assert_array_equal(out.diffuse.residual_variance, res.diffuse)
    np.testing.assert_array_equal(out.specular.residual_variance, res.specular)
    assert out.diffuse.rank == 4 and out.shared


def test_bad_input():
    d, s, sym = _population(0)
    with pytest.raises(InputError, match="at least 3"):
        loo_residual_variance(d[:2], s[:2], sym)
    with pytest.raises(InputError, match="differ"):
        loo_residual_variance(d, s[:, :-2], sym)
    with pytest.raises(InputError, match="variant"):
        loo_residual_variance(d, s, sym, variant="other")
