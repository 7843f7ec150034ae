"""A model's colour space: resolution rules and the sRGB texture curve (albedo_model.io.colour_space)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import colour
import h5py
import numpy as np
import pytest
from momo_factory import synthetic_model

from albedo_model.errors import InputError
from albedo_model.io.colour_space import (
    ColourSpace,
    colour_space_metadata,
    decode_texture,
    encode_texture,
    model_colour_space,
    resolve_colour_space,
)
from albedo_model.io.momo_h5 import INFO_PATH, read_model_h5, write_model_h5


def _with_metadata(model, metadata):
    return dataclasses.replace(model, metadata=metadata)


# -- resolution ---------------------------------------------------------------

@pytest.mark.parametrize("text, value", [
    ("linear sRGB", "linear"), ("linear", "linear"), ("Linear_sRGB", "linear"),
    ("sRGB", "srgb"), ("srgb", "srgb"), ("sRGB (gamma-encoded)", "srgb"),
    ("gamma-encoded sRGB", "srgb"),
])
def test_metadata_names_the_colour_space(text, value):
    for specular in (True, False):  # the metadata wins over the layout
        model = _with_metadata(synthetic_model(specular=specular), {"colour_space": text})
        space = model_colour_space(model)
        assert (space.value, space.source) == (value, "model metadata")


def test_layout_defaults_when_the_metadata_says_nothing():
    # AlbedoMM's diffuse/specular split: linear albedo
    albedomm = _with_metadata(synthetic_model(specular=True), {"colour_space": "RGB"})
    assert model_colour_space(albedomm) == ColourSpace(
        "linear", "layout default", model_colour_space(albedomm).label)
    # a colour-only model from a scalismo MoMo file (BFM 2017): an sRGB texture
    bfm = _with_metadata(synthetic_model(specular=False),
                         {"source_format": "scalismo MoMo HDF5", "colour_space": "RGB"})
    space = model_colour_space(bfm)
    assert (space.value, space.source) == ("srgb", "layout default")
    assert "BFM" in space.label and space.is_srgb
    # a model built in memory without any hint: linear, as before the choice existed
    bare = _with_metadata(synthetic_model(specular=False), {})
    assert model_colour_space(bare).value == "linear"
    assert model_colour_space(bare).source == "default"


def test_the_readers_guess_for_foreign_files_is_not_metadata():
    # the reader writes colour_space "linear sRGB" for any foreign AlbedoMM file: that is
    # the layout speaking, and is reported so
    md = {"source_format": "AlbedoMM HDF5", "colour_space": "linear sRGB"}
    space = resolve_colour_space(md, has_specular=True)
    assert (space.value, space.source) == ("linear", "layout default")


def test_override_wins_and_bad_values_are_clear_errors():
    model = synthetic_model()  # metadata: linear sRGB
    space = model_colour_space(model, "srgb")
    assert (space.value, space.source) == ("srgb", "override")
    assert "srgb" in space.describe() and "override" in space.describe()
    assert model_colour_space(model, "linear").source == "override"
    for bad in ("sRGB", "gamma", "", 1):
        with pytest.raises(InputError, match="'linear' or 'srgb'"):
            model_colour_space(model, bad)


def test_metadata_helper_round_trips_through_a_file(tmp_path: Path):
    for value in ("linear", "srgb"):
        md = colour_space_metadata(value)
        model = _with_metadata(synthetic_model(specular=False), md)
        write_model_h5(model, tmp_path / f"{value}.h5")
        read = read_model_h5(tmp_path / f"{value}.h5")
        assert model_colour_space(read) == model_colour_space(model)
        assert model_colour_space(read).source == "model metadata"
    with pytest.raises(InputError):
        colour_space_metadata("gamma")


def test_a_momo_file_written_elsewhere_reads_as_srgb(tmp_path: Path):
    path = tmp_path / "bfm-like.h5"
    write_model_h5(_with_metadata(synthetic_model(specular=False), {}), path)
    with h5py.File(path, "a") as h5:  # drop our metadata: what a scalismo-written file looks like
        del h5[INFO_PATH]
    space = model_colour_space(read_model_h5(path))
    assert (space.value, space.source) == ("srgb", "layout default")


def test_scalismo_momo_fixture_is_an_srgb_texture(shared_data: Path):
    model = read_model_h5(shared_data / "scalismo" / "random-momo.h5")
    assert model_colour_space(model).value == "srgb"


# -- the texture curve ----------------------------------------------------------

def test_decode_and_encode_match_colour_science_and_round_trip():
    x = np.linspace(-0.05, 1.1, 2001)
    assert np.allclose(decode_texture(x), colour.cctf_decoding(x, function="sRGB"),
                       rtol=0, atol=1e-15)
    assert np.allclose(encode_texture(x), colour.cctf_encoding(x, function="sRGB"),
                       rtol=0, atol=1e-15)
    assert np.allclose(encode_texture(decode_texture(x)), x, atol=1e-12)
    assert np.allclose(decode_texture(encode_texture(x)), x, atol=1e-12)
    # the IEC 61966-2-1 curve: linear segment below 0.04045, 2.4 power above
    assert decode_texture(np.array(0.04)) == pytest.approx(0.04 / 12.92)
    assert decode_texture(np.array(0.5)) == pytest.approx(((0.5 + 0.055) / 1.055) ** 2.4)


def test_texture_curve_keeps_float32_and_shape_and_copies():
    x = np.random.default_rng(0).uniform(size=(5, 3)).astype(np.float32)
    y = decode_texture(x)
    assert y.dtype == np.float32 and y.shape == (5, 3) and y is not x
    assert decode_texture(x.astype(np.float64)).dtype == np.float64
    assert encode_texture([0.0, 1.0]).dtype == np.float64
    assert np.array_equal(x, x.copy())  # input untouched
