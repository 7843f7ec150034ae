"""PNG reading keeps 16-bit samples (Pillow alone reduces 16-bit RGB to 8 bits)."""

from __future__ import annotations

import numpy as np
import pytest

from albedo_model.errors import FormatError
from albedo_model.io.image_io import read_image, read_image_pixels, write_png


@pytest.mark.parametrize("alpha", [False, True])
@pytest.mark.parametrize("grey", [False, True])
def test_sixteen_bit_png_round_trips_to_half_a_step(tmp_path, grey, alpha):
    rng = np.random.default_rng(0)
    img = rng.uniform(size=(7, 11) if grey else (7, 11, 3))
    path = tmp_path / "x.png"
    write_png(path, img, bits=16, alpha=np.ones((7, 11)) if alpha else None)
    pixels = read_image_pixels(path)
    assert pixels.dtype == np.uint16 and pixels.shape == (7, 11, 3)
    back = read_image(path)
    want = np.repeat(img[..., None], 3, axis=2) if grey else img
    assert np.abs(back - want).max() <= 0.5 / 65535 + 1e-12


def test_eight_bit_png_stays_eight_bit(tmp_path):
    img = np.random.default_rng(1).uniform(size=(5, 4, 3))
    write_png(tmp_path / "x.png", img)
    assert read_image_pixels(tmp_path / "x.png").dtype == np.uint8
    assert np.abs(read_image(tmp_path / "x.png") - img).max() <= 0.5 / 255 + 1e-12


def test_a_truncated_sixteen_bit_png_is_a_format_error(tmp_path):
    path = tmp_path / "x.png"
    write_png(path, np.zeros((20, 20, 3)), bits=16)
    path.write_bytes(path.read_bytes()[:60])
    with pytest.raises(FormatError, match="x.png: not a readable image"):
        read_image(path)
