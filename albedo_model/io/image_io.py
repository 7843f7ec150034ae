"""Reading and writing images (PNG/JPEG) with clear errors and atomic writes.

Images are float arrays in [0, 1]; 8-bit files are value/255 (scalismo's
convention), 16-bit files value/65535.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from albedo_model.errors import FormatError, InputError
from albedo_model.io.atomic import atomic_path

__all__ = ["read_image", "write_png"]


def read_image(path: str | os.PathLike) -> np.ndarray:
    """Read an RGB image as float64 in [0, 1], shape (H, W, 3).

    Grey images are replicated to three channels; an alpha channel is dropped.
    """
    import imageio.v3 as iio

    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: file not found")
    try:
        a = np.asarray(iio.imread(p))
    except Exception as exc:  # imageio raises many types for corrupt files
        raise FormatError(p, f"not a readable image ({type(exc).__name__})") from None
    if a.dtype == np.uint8:
        img = a / 255.0
    elif a.dtype == np.uint16:
        img = a / 65535.0
    elif a.dtype.kind == "f":
        img = a.astype(np.float64)
    else:
        raise FormatError(p, f"unsupported pixel type {a.dtype}")
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    if img.ndim != 3 or img.shape[2] not in (3, 4) or min(img.shape[:2]) < 1:
        raise FormatError(p, f"unsupported image shape {a.shape}")
    return np.ascontiguousarray(img[..., :3])


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
