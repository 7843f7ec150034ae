"""Low-level pieces of the scalismo (statismo 0.9) MoMo HDF5 layout.

Owns: fixed-length string datasets and attributes, version groups, one PCA
part group (``model/``, ``version/``, ``modelinfo/``, ``representer/``) and the
landmark strings embedded under ``/metadata/landmarks``. The whole-file
layouts (MoMo, AlbedoMM, albedo part) are in :mod:`albedo_model.io.momo_h5`.

Every read goes through :class:`H5Reader`, which turns h5py/OS errors and
layout violations into :class:`~albedo_model.errors.FormatError` naming the
file.

This module imports only :mod:`albedo_model.errors`, :mod:`albedo_model.pca` and
:mod:`albedo_model.io.tlms`.
"""

from __future__ import annotations

import contextlib
import json
import os
import time
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from albedo_model.errors import FormatError, InputError
from albedo_model.io.tlms import parse_tlms_text
from albedo_model.pca import PCAPart

__all__ = [
    "H5Reader", "error_text", "Representer", "write_text", "write_text_attr", "write_version",
    "read_pca_group", "write_pca_group", "parse_landmarks_json", "parse_tlms3d_text",
    "landmarks_to_json", "REPRESENTER_NAMES",
]

#: ``representer`` ``name`` attribute of each part group.
REPRESENTER_NAMES = {
    "shape": "gravis::MeshShapeRepresenter",
    "color": "gravis::MeshColorRepresenter",
    "expression": "gravis::MeshExpressionRepresenter",
    "diffuseAlbedo": "gravis::MeshDiffuseAlbedoRepresenter",
    "specularAlbedo": "gravis::MeshSpecularAlbedoRepresenter",
}
_LEGACY_REPRESENTER = "gravis::Mesh Shape Representer"


def error_text(exc: BaseException) -> str:
    """Squeeze an exception message onto one line."""
    return " ".join(str(exc).split()) or type(exc).__name__


def _text(value: Any, what: str, path: str) -> str:
    """Decode a string value as h5py returns it: bytes, str, () or (1,) array."""
    if isinstance(value, np.ndarray):
        if value.size != 1:
            raise FormatError(path, f"{what} must hold one string, got shape {value.shape}")
        value = value.reshape(-1)[0]
    if isinstance(value, (bytes, np.bytes_)):
        try:
            value = bytes(value).decode("utf-8")
        except UnicodeDecodeError:
            raise FormatError(path, f"{what} is not UTF-8 text") from None
    if not isinstance(value, str):
        raise FormatError(path, f"{what} is not a string")
    return value.rstrip("\0")


class Representer:
    """Reference mesh of one part: ``points`` (n, 3) float32, ``cells`` (m, 3) int32."""

    __slots__ = ("points", "cells")

    def __init__(self, points: np.ndarray, cells: np.ndarray) -> None:
        self.points = points
        self.cells = cells

    def same_as(self, other: Representer) -> bool:
        """Equal point and cell arrays (exact, as scalismo compares point sets)."""
        return (
            self.points.shape == other.points.shape and self.cells.shape == other.cells.shape
            and np.array_equal(self.points, other.points)
            and np.array_equal(self.cells, other.cells)
        )


class H5Reader:
    """Checked access to an open HDF5 file; every failure is a FormatError.

    Parameters
    ----------
    h5 : h5py.File
        The open file.
    path : str or PathLike
        File name used in error messages.
    """

    def __init__(self, h5: h5py.File, path: str | os.PathLike) -> None:
        self.h5 = h5
        self.path = os.fspath(path)

    def error(self, reason: str) -> FormatError:
        """Return a FormatError for this file."""
        return FormatError(self.path, reason)

    def has(self, name: str) -> bool:
        """Whether ``name`` (group or dataset) exists."""
        try:
            return name in self.h5
        except (OSError, KeyError, ValueError, RuntimeError):
            return False

    def array(
        self, name: str, *, ndim: int | None = None, kind: str = "f", finite: bool = True
    ) -> np.ndarray:
        """Read dataset ``name`` as an array, checking rank, dtype kind and finiteness.

        ``kind`` is a string of accepted numpy dtype kinds ("f", "iu", ...).
        """
        node = self.h5.get(name) if self.has(name) else None
        if not isinstance(node, h5py.Dataset):
            raise self.error(f"missing dataset {name}")
        try:
            value = np.asarray(node[()])
        except (OSError, ValueError, TypeError, RuntimeError) as exc:
            raise self.error(f"cannot read {name} ({error_text(exc)})") from None
        if value.dtype.kind not in kind:
            raise self.error(f"{name} has dtype {value.dtype}, expected a numeric array")
        if ndim is not None and value.ndim != ndim:
            raise self.error(f"{name} has shape {value.shape}, expected {ndim} dimension(s)")
        if finite and value.dtype.kind == "f" and not np.all(np.isfinite(value)):
            raise self.error(f"{name} contains NaN or infinite values")
        return value

    def shape_of(self, name: str) -> tuple[int, ...] | None:
        """Shape of dataset ``name`` without reading it, or None when absent."""
        node = self.h5.get(name) if self.has(name) else None
        return tuple(node.shape) if isinstance(node, h5py.Dataset) else None

    def scalar(self, name: str, *, default: float | None = None) -> float:
        """Read a number stored as a () or (1,) dataset; ``default`` when absent."""
        if default is not None and not self.has(name):
            return default
        value = self.array(name, kind="fiu")
        if value.size != 1:
            raise self.error(f"{name} must hold one number, got shape {value.shape}")
        return value.reshape(-1)[0].item()

    def text(self, name: str) -> str:
        """Read a string dataset (fixed-length or variable, shape () or (1,))."""
        node = self.h5.get(name) if self.has(name) else None
        if not isinstance(node, h5py.Dataset):
            raise self.error(f"missing dataset {name}")
        try:
            value = node[()]
        except (OSError, ValueError, TypeError, RuntimeError) as exc:
            raise self.error(f"cannot read {name} ({error_text(exc)})") from None
        return _text(value, name, self.path)

    def text_attr(self, name: str, attr: str) -> str | None:
        """Read string attribute ``attr`` of ``name``, or None when absent."""
        try:
            attrs = self.h5[name].attrs
            if attr not in attrs:
                return None
            value = attrs[attr]
        except (OSError, KeyError, ValueError, TypeError, RuntimeError) as exc:
            reason = f"cannot read attribute {attr} of {name} ({error_text(exc)})"
            raise self.error(reason) from None
        return _text(value, f"attribute {attr} of {name}", self.path)

    def version(self, group: str) -> tuple[int, int]:
        """(major, minor) of ``group/version``; statismo's default is 0.8 when absent."""
        major = int(self.scalar(f"{group}/version/majorVersion", default=0))
        minor = int(self.scalar(f"{group}/version/minorVersion", default=8))
        return major, minor

    def representer(self, group: str) -> Representer:
        """Read the reference mesh stored in ``group/representer``.

        Cells may be int32 or legacy uint32; they are returned as int32 and must
        index the points. The legacy ``gravis::Mesh Shape Representer`` layout
        (``reference-mesh/vertex-coordinates`` (n, 3), ``triangle-list`` (m, 3))
        is read too.
        """
        rep = f"{group}/representer"
        if not self.has(rep):
            raise self.error(f"missing group {rep}")
        if self.text_attr(rep, "name") == _LEGACY_REPRESENTER:
            points = self.array(f"{rep}/reference-mesh/vertex-coordinates", ndim=2).T
            cells = self.array(f"{rep}/reference-mesh/triangle-list", ndim=2, kind="iu").T
        else:
            points = self.array(f"{rep}/points", ndim=2)
            cells = self.array(f"{rep}/cells", ndim=2, kind="iu")
        if points.shape[0] != 3:
            raise self.error(f"{rep} points have shape {points.shape}, expected (3, n)")
        if cells.shape[0] != 3:
            raise self.error(f"{rep} cells have shape {cells.shape}, expected (3, m)")
        n = points.shape[1]
        if cells.size and (int(cells.min()) < 0 or int(cells.max()) >= n):
            raise self.error(f"{rep} cells index outside the {n} points")
        return Representer(
            np.ascontiguousarray(points.T.astype(np.float32, copy=False)),
            np.ascontiguousarray(cells.T.astype(np.int32)),
        )


@contextlib.contextmanager
def open_h5(path: str | os.PathLike) -> Iterator[H5Reader]:
    """Open an HDF5 file for checked reading.

    Raises
    ------
    InputError
        The file does not exist.
    FormatError
        The file is not HDF5, is truncated, or fails while being read.
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: file not found")
    try:
        h5 = h5py.File(p, "r")
    except OSError as exc:
        raise FormatError(p, f"not a readable HDF5 file ({error_text(exc)})") from None
    try:
        yield H5Reader(h5, p)
    except (OSError, KeyError, RuntimeError) as exc:
        raise FormatError(p, f"cannot read the file ({error_text(exc)})") from None
    finally:
        h5.close()


def read_pca_group(reader: H5Reader, group: str, n_vertices: int) -> PCAPart:
    """Read the PCA part stored at ``group`` (``/shape``, ``/color``, ...).

    Parameters
    ----------
    reader : H5Reader
    group : str
        Part group path.
    n_vertices : int
        Vertices of the reference mesh; the part must have dimension ``3 n``.

    Returns
    -------
    PCAPart
        float32 mean (3n,) and basis (3n, k) as stored, float32 variance (k,).
        For version 0.8 parts (columns ``U sqrt(lambda)``) the columns are
        renormalised to unit length, as scalismo does; the variances are those
        stored in ``pcaVariance``.
    """
    major, minor = reader.version(group)
    if (major, minor) not in ((0, 8), (0, 9)) and major != 1:
        raise reader.error(f"{group} has unsupported statismo version {major}.{minor}")
    mean = reader.array(f"{group}/model/mean", ndim=1)
    basis = reader.array(f"{group}/model/pcaBasis", ndim=2)
    variance = reader.array(f"{group}/model/pcaVariance", ndim=1)
    noise = reader.scalar(f"{group}/model/noiseVariance", default=0.0)
    d = 3 * n_vertices
    if mean.shape != (d,):
        raise reader.error(f"{group}/model/mean has shape {mean.shape}, expected ({d},) for "
                           f"{n_vertices} vertices")
    if basis.shape[0] != d:
        raise reader.error(f"{group}/model/pcaBasis has shape {basis.shape}, expected ({d}, k)")
    if variance.shape != (basis.shape[1],):
        raise reader.error(f"{group}/model/pcaVariance has shape {variance.shape}, expected "
                           f"({basis.shape[1]},)")
    if np.any(variance < 0):
        raise reader.error(f"{group}/model/pcaVariance has negative values")
    if (major, minor) == (0, 8):
        norms = np.sqrt(np.einsum("ij,ij->j", basis, basis, dtype=np.float64))
        # columns already of unit length stay bit-identical (files without a
        # version group default to 0.8 but usually hold orthonormal columns)
        if np.any(np.abs(norms - 1.0) > 1e-6):
            scale = np.divide(1.0, norms, out=np.zeros_like(norms), where=norms > 0)
            scale[np.abs(norms - 1.0) <= 1e-6] = 1.0
            basis = (basis.astype(np.float64) * scale).astype(basis.dtype)
    try:
        return PCAPart(mean, basis, variance, float(noise))
    except InputError as exc:
        raise reader.error(f"{group}: {exc}") from None


# -- writing -----------------------------------------------------------------

def write_text(group: h5py.Group, name: str, text: str, *, nul: bool = False) -> None:
    """Write ``text`` as a fixed-length byte string of shape (1,).

    ``nul=True`` appends the C terminator that statismo stores for ``colorspace``.
    """
    data = text.encode("utf-8") + (b"\0" if nul else b"")
    group.create_dataset(name, data=np.array([data], dtype=f"S{max(len(data), 1)}"))


def write_text_attr(obj: h5py.HLObject, name: str, text: str) -> None:
    """Write a string attribute as statismo does: fixed length incl. terminator, shape (1,)."""
    data = text.encode("utf-8")
    obj.attrs.create(name, np.array([data], dtype=f"S{len(data) + 1}"))


def write_version(group: h5py.Group, major: int = 0, minor: int = 9) -> None:
    """``version/{majorVersion, minorVersion}`` as int32 scalars."""
    g = group.require_group("version")
    g.create_dataset("majorVersion", data=np.int32(major))
    g.create_dataset("minorVersion", data=np.int32(minor))


def write_pca_group(
    h5: h5py.File,
    group: str,
    part: PCAPart,
    vertices: np.ndarray,
    triangles: np.ndarray,
    *,
    colorspace: bool = False,
) -> None:
    """Write one part in the statismo 0.9 layout.

    Parameters
    ----------
    h5 : h5py.File
        File open for writing.
    group : str
        ``shape``, ``color``, ``expression``, ``diffuseAlbedo`` or ``specularAlbedo``.
    part : PCAPart
        Stored as float32 ``mean`` (3n,), ``pcaBasis`` (3n, k), ``pcaVariance``
        (k,), ``noiseVariance`` (1,).
    vertices : (n, 3) float array
        Representer points, stored float32 (3, n).
    triangles : (m, 3) int array
        Representer cells, stored int32 (3, m).
    colorspace : bool
        Add ``representer/colorspace`` = "RGB" plus a NUL byte (colour parts).
    """
    g = h5.create_group(group)
    write_version(g)
    m = g.create_group("model")
    m.create_dataset("mean", data=np.asarray(part.mean, np.float32))
    m.create_dataset("pcaBasis", data=np.asarray(part.basis, np.float32))
    m.create_dataset("pcaVariance", data=np.asarray(part.variance, np.float32))
    m.create_dataset("noiseVariance", data=np.array([part.noise_variance], np.float32))
    info = g.create_group("modelinfo")
    write_text(info, "build-time", time.strftime("%a %b %d %H:%M:%S %Z %Y"))
    info.create_dataset("scores", data=np.zeros((1, 1), np.float32))
    rep = g.create_group("representer")
    write_text_attr(rep, "name", REPRESENTER_NAMES[group])
    write_text_attr(rep, "datasetType", "POLYGON_MESH")
    rep.create_dataset("points", data=np.ascontiguousarray(np.asarray(vertices, np.float32).T))
    rep.create_dataset("cells", data=np.ascontiguousarray(np.asarray(triangles, np.int32).T))
    if colorspace:
        write_text(rep, "colorspace", "RGB", nul=True)


# -- landmarks embedded in the model file ------------------------------------

def parse_landmarks_json(text: str, path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Parse ``[{"id": name, "coordinates": [x, y, z]}, ...]`` (extra keys ignored)."""
    try:
        items = json.loads(text)
    except json.JSONDecodeError as exc:
        raise FormatError(path, f"landmark JSON is malformed ({exc.msg})") from None
    if not isinstance(items, list):
        raise FormatError(path, "landmark JSON must be a list of {id, coordinates}")
    out: dict[str, np.ndarray] = {}
    for i, item in enumerate(items):
        try:
            name = item["id"]
            coords = np.array(item["coordinates"], dtype=np.float64)
        except (KeyError, TypeError, ValueError):
            raise FormatError(path, f"landmark {i} lacks a string id and 3 coordinates") from None
        if not isinstance(name, str) or coords.shape != (3,) or not np.all(np.isfinite(coords)):
            raise FormatError(path, f"landmark {i} lacks a string id and 3 finite coordinates")
        out[name] = coords
    return out


def parse_tlms3d_text(text: str, path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Parse embedded TLMS-3D lines ``name visible x y z`` (the visibility flag is not kept)."""
    try:
        items = parse_tlms_text(text, 3, source=path)
    except FormatError as exc:
        raise FormatError(path, f"landmark text: {exc.reason}") from None
    return {lm.name: np.array(lm.point, np.float64) for lm in items}


def landmarks_to_json(landmarks: Mapping[str, np.ndarray]) -> str:
    """JSON list ``[{"id", "coordinates"}]``; floats written with exact round trip."""
    items = [
        {"id": name, "coordinates": [float(c) for c in np.asarray(p, np.float64)]}
        for name, p in landmarks.items()
    ]
    return json.dumps(items, separators=(",", ":")) + "\n"
