"""Posterior albedo of an sRGB-texture model reported in linear albedo (mcmcfit.outputs.albedo_decoding)."""

from __future__ import annotations

import numpy as np
import pytest

from albedo_model.errors import InputError
from albedo_model.io.colour_space import ColourSpace, decode_texture
from albedo_model.pca import PCAPart
from mcmcfit.outputs.albedo_decoding import (
    COLOUR_HANDLING,
    decoded_albedo_posterior,
    model_colour_record,
)
from mcmcfit.outputs.posterior import albedo_posterior


def _part(n: int = 40, k: int = 3, *, sd: float = 0.05, residual: float | None = None,
          seed: int = 0) -> PCAPart:
    rng = np.random.default_rng(seed)
    basis = np.linalg.qr(rng.standard_normal((3 * n, k)))[0]
    mean = rng.uniform(0.3, 0.8, 3 * n)
    part = PCAPart(mean, basis, np.full(k, sd ** 2 * 3 * n), 0.0)
    return part if residual is None else part.with_residual_variance(np.full(3 * n, residual ** 2))


def test_summaries_are_those_of_the_decoded_samples():
    part = _part()
    c = np.random.default_rng(1).standard_normal((500, 3))
    post = decoded_albedo_posterior(part, c, level=0.9, block_rows=17)
    x = decode_texture(part.mean[None, :] + c @ part.scaled_basis.T)   # (S, 3n) linear
    assert np.allclose(post.mean, x.mean(0).reshape(-1, 3), atol=1e-6)
    assert np.allclose(post.std, x.std(0).reshape(-1, 3), atol=1e-6)
    assert np.allclose(post.lo, np.quantile(x, 0.05, axis=0).reshape(-1, 3), atol=1e-6)
    assert np.allclose(post.hi, np.quantile(x, 0.95, axis=0).reshape(-1, 3), atol=1e-6)
    assert not post.predictive and post.level == 0.9
    # not the decoded mean instance, and nowhere near the encoded summaries
    enc = albedo_posterior(part, c)
    assert np.abs(post.mean - enc.mean).min() > 0.05
    # the decoding is convex there: the mean of decoded samples lies above the decoded mean
    assert np.all(post.mean >= decode_texture(enc.mean) - 1e-6)


def test_predictive_summaries_add_the_residual_in_the_encoded_space():
    part = _part(sd=0.02, residual=0.05)
    c = np.random.default_rng(2).standard_normal((400, 3))
    post = decoded_albedo_posterior(part, c, rng=np.random.default_rng(0), min_draws=4000)
    assert post.predictive
    only = post.coefficient_only()
    assert np.all(post.std > only.std)
    assert np.all(post.hi - post.lo > only.hi - only.lo)
    # residual sd carried to linear units: about sd x slope of the decoding at the mean
    slope = 2.4 / 1.055 * ((part.mean + 0.055) / 1.055) ** 1.4
    assert np.allclose(post.residual_std, (0.05 * slope).reshape(-1, 3), rtol=1e-3)
    # the Monte Carlo predictive variance matches coefficient variance + residual term
    expect = np.sqrt(only.std.astype(float) ** 2 + (0.05 * slope.reshape(-1, 3)) ** 2)
    assert np.allclose(post.std, expect, rtol=0.1)


def test_mean_instance_and_bad_inputs():
    part = _part()
    post = decoded_albedo_posterior(part, np.zeros((1, 0)))
    assert np.allclose(post.mean, decode_texture(part.mean).reshape(-1, 3), atol=1e-6)
    assert np.all(post.std == 0)
    with pytest.raises(InputError):
        decoded_albedo_posterior(part, np.zeros((3, 5)))
    with pytest.raises(InputError):
        decoded_albedo_posterior(part, np.zeros((3, 2)), level=1.0)


def test_model_record_names_value_source_and_handling():
    rec = model_colour_record(ColourSpace("srgb", "layout default", "sRGB texture"))
    assert rec == {"colour_space": "srgb", "colour_space_source": "layout default",
                   "colour_space_label": "sRGB texture",
                   "colour_handling": COLOUR_HANDLING["srgb"]}
    assert "decoded" in rec["colour_handling"] and "\n" not in rec["colour_handling"]
    assert "linearised" in model_colour_record(
        ColourSpace("linear", "default", "x"))["colour_handling"]
