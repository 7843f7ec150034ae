"""Reading and writing images (PNG/JPEG) with clear errors and atomic writes.

Images are float arrays in [0, 1]; 8-bit files are value/255 (scalismo's
convention), 16-bit files value/65535. :func:`read_image_pixels` reads the
same RGB pixels without that conversion, keeping their stored 8- or 16-bit
integers (no float copy of a 10-megapixel photograph). 16-bit PNGs are decoded
with pypng: Pillow (imageio's default) reduces 16-bit RGB to 8 bits.

This module imports only :mod:`albedo_model.errors` and
:mod:`albedo_model.io.atomic`.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from albedo_model.errors import FormatError, InputError
from albedo_model.io.atomic import atomic_path

__all__ = ["read_image", "read_image_pixels", "write_png"]


def _read_rgb(path: str | os.PathLike, *, name_stored_shape: bool) -> np.ndarray:
    """Read RGB pixels as stored: (H, W, 3) uint8, uint16 or float, possibly a view.

    ``name_stored_shape`` picks the shape an "unsupported image shape" error
    names for an empty grey image: the file's (H, W) or the replicated (H, W, 3).
    """
    import imageio.v3 as iio

    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: file not found")
    try:
        stored = _png16(p)
        if stored is None:
            stored = np.asarray(iio.imread(p))
    except Exception as exc:  # imageio and pypng raise many types for corrupt files
        raise FormatError(p, f"not a readable image ({type(exc).__name__})") from None
    if stored.dtype not in (np.uint8, np.uint16) and stored.dtype.kind != "f":
        raise FormatError(p, f"unsupported pixel type {stored.dtype}")
    if stored.ndim == 3 and stored.shape[2] == 2:  # grey + alpha
        stored = stored[..., 0]
    a = np.repeat(stored[..., None], 3, axis=2) if stored.ndim == 2 else stored
    if a.ndim != 3 or a.shape[2] not in (3, 4) or min(a.shape[:2]) < 1:
        shape = stored.shape if name_stored_shape else a.shape
        raise FormatError(p, f"unsupported image shape {shape}")
    return a[..., :3] if a.shape[2] == 4 else a


def _png16(path: Path) -> np.ndarray | None:
    """Read a 16-bit PNG's samples as uint16 (H, W[, planes]); None for any other file."""
    with open(path, "rb") as fh:
        head = fh.read(25)
    # PNG signature, then the IHDR chunk: bit depth is byte 24
    if head[:8] != b"\x89PNG\r\n\x1a\n" or len(head) < 25 or head[24] != 16:
        return None
    import png

    width, height, rows, info = png.Reader(filename=str(path)).asDirect()
    data = np.vstack([np.asarray(r, np.uint16) for r in rows])
    planes = info["planes"]
    return data.reshape(height, width, planes) if planes > 1 else data.reshape(height, width)


def read_image_pixels(path: str | os.PathLike) -> np.ndarray:
    """Read an RGB image keeping its stored pixel type, shape (H, W, 3).

    Grey images are replicated to three channels; an alpha channel is dropped
    (the result is then a view of the decoded RGBA array).

    Parameters
    ----------
    path : path-like
        A PNG, JPEG or any other file imageio reads.

    Returns
    -------
    (H, W, 3) uint8, uint16 or float array
        The pixels unscaled, as the file stores them (float files keep their
        float type).

    Raises
    ------
    InputError
        The file does not exist.
    FormatError
        Not a readable image, or an unsupported pixel type or shape.
    """
    return _read_rgb(path, name_stored_shape=False)


def read_image(path: str | os.PathLike) -> np.ndarray:
    """Read an RGB image as float64 in [0, 1], shape (H, W, 3).

    The pixels of :func:`read_image_pixels` (grey replicated, alpha dropped,
    the same errors), 8-bit values divided by 255, 16-bit ones by 65535, float
    files converted to float64 unscaled.

    Parameters
    ----------
    path : path-like
        The image file.

    Returns
    -------
    (H, W, 3) float64
        C-contiguous.
    """
    a = _read_rgb(path, name_stored_shape=True)
    if a.dtype == np.uint8:
        img = a / 255.0
    elif a.dtype == np.uint16:
        img = a / 65535.0
    else:
        img = a.astype(np.float64)
    return np.ascontiguousarray(img)


def write_png(path: str | os.PathLike, image: np.ndarray, *, alpha: np.ndarray | None = None,
              bits: int = 8) -> None:
    """Write a float image in [0, 1] as an 8- or 16-bit PNG (atomically).

    Parameters
    ----------
    path : path-like
    image : (H, W, 3) or (H, W) float array, clipped to [0, 1]
    alpha : (H, W) bool or float array, optional
        Written as the fourth channel.
    bits : {8, 16}
    """
    if bits not in (8, 16):
        raise InputError(f"bits must be 8 or 16, got {bits}")
    img = np.asarray(image, np.float64)
    if alpha is not None:
        img = np.dstack([img, np.asarray(alpha, np.float64)])
    img = np.nan_to_num(np.clip(img, 0.0, 1.0))
    top = 255 if bits == 8 else 65535
    data = np.round(img * top).astype(np.uint8 if bits == 8 else np.uint16)
    import png  # pypng: writes 16-bit RGB(A), which Pillow cannot

    h, w = data.shape[:2]
    planes = 1 if data.ndim == 2 else data.shape[2]
    writer = png.Writer(w, h, greyscale=planes in (1, 2), alpha=planes in (2, 4), bitdepth=bits)
    with atomic_path(path, suffix=".png") as tmp, open(tmp, "wb") as fh:
        writer.write(fh, data.reshape(h, w * planes))
