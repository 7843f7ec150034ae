"""AlbedoMM's FLAME albedo model (``albedoModel2020_FLAME_albedoPart.npz``).

The release is a **texture-space** PCA: there is no mesh, only UV maps.
Supported keys (loaded with ``allow_pickle=False``; extra keys are ignored):

=========  ==========================  ===========================================
key        shape                       meaning
=========  ==========================  ===========================================
``MU``     (H, W, 3) or (d,) / (n, 3)  diffuse albedo mean (H = W = 512 in the
                                       release), values in [0, 1]
``PC``     MU.shape + (k,)             diffuse components, **scaled**: the model
                                       is ``MU + PC c`` with c ~ N(0, I) (k = 145)
``specMU`` like ``MU``                 specular albedo mean (optional)
``specPC`` like ``PC``                 specular components, driven by the same c
``vt``     (t, 2)                      UV coordinates (optional)
``ft``     (m, 3)                      UV index per FLAME triangle (optional)
=========  ==========================  ===========================================

The texture channels are stored in **BGR** order (TF_FLAME's
``sample_texture.py`` writes them with ``cv2.imwrite`` unchanged); by default
the reader reverses the last axis to RGB. The scaled columns are split into
unit columns and variances (``lambda_j = ||PC_j||^2``), which reproduces
``MU + PC c`` exactly for the same coefficients; the release's columns are
orthogonal only up to the texture resampling AlbedoMM did, so
:meth:`PCAPart.project` is approximate there. Rows keep the file's image order
(row 0 = top, v = 1).

This module imports only :mod:`albedo_model.errors`, :mod:`albedo_model.pca` and
:mod:`albedo_model.io.atomic`.
"""

from __future__ import annotations

import os
import zipfile
from pathlib import Path
from typing import NamedTuple

import numpy as np

from albedo_model.errors import FormatError, InputError
from albedo_model.io.atomic import atomic_path
from albedo_model.pca import PCAPart

__all__ = ["FlameAlbedo", "read_flame_albedo_npz", "write_flame_albedo_npz"]

_ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")


class FlameAlbedo(NamedTuple):
    """A texture-space albedo model.

    Attributes
    ----------
    diffuse : PCAPart
        Over the flattened texture, dimension ``H*W*3`` in row-major (H, W, RGB)
        order (or the stored per-vertex layout for 1-D/2-D means).
    specular : PCAPart or None
        Same layout and rank, driven by the diffuse coefficients.
    texture_shape : tuple of int
        Shape of one map, ``(H, W, 3)`` for the release.
    uv : (t, 2) float array or None
        ``vt``.
    uv_faces : (m, 3) int array or None
        ``ft``.
    """

    diffuse: PCAPart
    specular: PCAPart | None
    texture_shape: tuple[int, ...]
    uv: np.ndarray | None = None
    uv_faces: np.ndarray | None = None


def _load(path: Path) -> np.lib.npyio.NpzFile:
    if not path.is_file():
        raise InputError(f"{path}: file not found")
    with path.open("rb") as fh:
        head = fh.read(6)
    if head[:4] not in _ZIP_MAGIC:
        if head.startswith(b"\x93NUMPY"):
            raise FormatError(path, "a single .npy array, not an .npz archive")
        if head[:1] == b"\x80":
            raise FormatError(path, "a Python pickle; needs pickle; refusing to unpickle")
        raise FormatError(path, "not an .npz archive")
    try:
        return np.load(path, allow_pickle=False)
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise FormatError(path, f"cannot open the archive ({exc})") from None


def _get(z: np.lib.npyio.NpzFile, key: str, path: Path) -> np.ndarray:
    try:
        value = np.asarray(z[key])
    except ValueError as exc:
        if "pickle" in str(exc):
            raise FormatError(path, f"array {key!r} needs pickle; refusing to unpickle") from None
        raise FormatError(path, f"cannot read array {key!r} ({exc})") from None
    except (OSError, EOFError, zipfile.BadZipFile) as exc:
        raise FormatError(path, f"cannot read array {key!r} ({exc})") from None
    if value.dtype.kind not in "fiu":
        raise FormatError(path, f"array {key!r} has dtype {value.dtype}, expected numbers")
    return value


def _part(
    mu: np.ndarray, pc: np.ndarray, names: tuple[str, str], path: Path, *,
    rank: int | None, dtype: np.dtype, bgr: bool,
) -> PCAPart:
    if pc.ndim < 2 or pc.shape[:-1] != mu.shape:
        raise FormatError(
            path, f"{names[1]} has shape {pc.shape}, expected {mu.shape} + (k,) to match {names[0]}"
        )
    k = pc.shape[-1] if rank is None else min(rank, pc.shape[-1])
    pc = pc[..., :k]
    for name, a in zip(names, (mu, pc), strict=True):
        if not np.all(np.isfinite(a)):
            raise FormatError(path, f"{name} contains NaN or infinite values")
    mean = mu.reshape(-1)
    cols = pc.reshape(-1, k)
    if bgr:
        if mean.size % 3:
            raise FormatError(path, f"{names[0]} has {mean.size} values, not RGB triples")
        mean = mean.reshape(-1, 3)[:, ::-1].reshape(-1)
        cols = cols.reshape(-1, 3, k)[:, ::-1, :].reshape(-1, k)
    norms = np.sqrt(np.einsum("ij,ij->j", cols, cols, dtype=np.float64))
    scale = np.divide(1.0, norms, out=np.zeros_like(norms), where=norms > 0)
    basis = cols.astype(dtype, copy=True)
    basis *= scale.astype(dtype)
    return PCAPart(mean.astype(dtype), basis, (norms**2).astype(dtype))


def read_flame_albedo_npz(
    path: str | os.PathLike,
    *,
    rank: int | None = None,
    dtype: np.dtype | type = np.float32,
    channel_order: str = "bgr",
) -> FlameAlbedo:
    """Read the AlbedoMM FLAME albedo model.

    Parameters
    ----------
    path : path-like
        ``.npz`` archive with the keys in the module docstring.
    rank : int, optional
        Keep only the first ``rank`` components (the release's two bases take
        about 0.9 GB each in float32 at full rank).
    dtype : numpy dtype
        Of the returned means, bases and variances.
    channel_order : {"bgr", "rgb"}
        Order of the stored channels; "bgr" (the release) is reversed to RGB.

    Returns
    -------
    FlameAlbedo

    Raises
    ------
    FormatError
        Not an npz archive, an array that needs pickle, missing ``MU``/``PC``,
        mismatched shapes, NaN values, or unequal diffuse/specular ranks.
    """
    if channel_order not in ("bgr", "rgb"):
        raise InputError(f"channel_order must be 'bgr' or 'rgb', got {channel_order!r}")
    p = Path(path)
    with _load(p) as z:
        keys = set(z.files)
        if not {"MU", "PC"} <= keys:
            found = ", ".join(sorted(keys)) or "none"
            raise FormatError(p, f"missing arrays MU and PC (found: {found})")
        if ("specMU" in keys) != ("specPC" in keys):
            raise FormatError(p, "specMU and specPC must both be present or both absent")
        opts = dict(rank=rank, dtype=np.dtype(dtype), bgr=channel_order == "bgr")
        mu = _get(z, "MU", p)
        diffuse = _part(mu, _get(z, "PC", p), ("MU", "PC"), p, **opts)
        specular = None
        if "specMU" in keys:
            spec_mu = _get(z, "specMU", p)
            if spec_mu.shape != mu.shape:
                raise FormatError(p, f"specMU has shape {spec_mu.shape}, MU has {mu.shape}")
            specular = _part(spec_mu, _get(z, "specPC", p), ("specMU", "specPC"), p, **opts)
            if specular.rank != diffuse.rank:
                raise FormatError(
                    p, f"specPC has {specular.rank} components, PC has {diffuse.rank}"
                )
        uv = _get(z, "vt", p) if "vt" in keys else None
        uv_faces = _get(z, "ft", p) if "ft" in keys else None
    if uv is not None and (uv.ndim != 2 or uv.shape[1] != 2):
        raise FormatError(p, f"vt has shape {uv.shape}, expected (t, 2)")
    if uv_faces is not None and (uv_faces.ndim != 2 or uv_faces.shape[1] != 3):
        raise FormatError(p, f"ft has shape {uv_faces.shape}, expected (m, 3)")
    return FlameAlbedo(diffuse, specular, tuple(mu.shape), uv, uv_faces)


def write_flame_albedo_npz(
    albedo: FlameAlbedo, path: str | os.PathLike, *, channel_order: str = "bgr"
) -> None:
    """Write ``albedo`` with the release's keys (scaled columns, BGR by default).

    ``read_flame_albedo_npz(write(...))`` returns the same model up to float
    rounding of the scale/unscale of the columns.
    """
    if channel_order not in ("bgr", "rgb"):
        raise InputError(f"channel_order must be 'bgr' or 'rgb', got {channel_order!r}")
    shape = tuple(albedo.texture_shape)
    arrays: dict[str, np.ndarray] = {}
    for prefix, part in (("", albedo.diffuse), ("spec", albedo.specular)):
        if part is None:
            continue
        mean = np.asarray(part.mean)
        cols = np.asarray(part.scaled_basis)
        if channel_order == "bgr":
            mean = mean.reshape(-1, 3)[:, ::-1].reshape(-1)
            cols = cols.reshape(-1, 3, part.rank)[:, ::-1, :].reshape(-1, part.rank)
        arrays[f"{prefix}MU"] = mean.reshape(shape)
        arrays[f"{prefix}PC"] = cols.reshape(*shape, part.rank)
    if albedo.uv is not None:
        arrays["vt"] = np.asarray(albedo.uv)
    if albedo.uv_faces is not None:
        arrays["ft"] = np.asarray(albedo.uv_faces)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays)
