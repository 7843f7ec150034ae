"""Morphable models in HDF5: scalismo MoMo (BFM 2017), AlbedoMM joint models, albedo parts.

Layouts (``reference-sampler.md`` §5), all statismo version 0.9:

* **MoMo**: ``/shape``, ``/color``, optional ``/expression``. The colour part is
  the model's ``diffuse`` part; ``specular`` is None.
* **AlbedoMM joint** (``albedoModel2020_{bfm,face12}.h5``): ``/color`` replaced by
  ``/diffuseAlbedo`` and ``/specularAlbedo``.
* **Albedo part** (``albedoModel2020_*_albedoPart.h5``): the two albedo groups
  with their representer and the landmarks. The AlbedoMM release files carry a
  dummy ``/shape`` group (rank 1, a 75-dimensional mean that does not match the
  mesh; see AlbedoMM ``notPublic/CombineModel.scala``); the reader ignores any
  ``/shape``. Our writer adds a valid placeholder ``/shape`` (the reference mesh,
  one zero-variance component) so AlbedoMM's own reader can open the file.

Reading accepts int32 and legacy uint32 cells, JSON or TLMS-3D landmark text,
fixed-length strings of shape (1,) or (), version 0.8 parts (columns
``U sqrt(lambda)``, renormalised) and per-part version 0.9. The model's
``vertices`` are the shape representer points (which need not equal the shape
mean). Project extras live under ``/metadata/mcmcfit`` (ignored by scalismo):
``info`` (JSON: layout, shared_albedo, metadata dict, exact float64 noise
variances), ``symmetry`` (int32 (n,)), ``uv`` (the UV atlas: float32 ``coordinates``
(t, 2), int32 ``triangles`` (m, 3)), and, for parts that have one, the
per-row residual variance (:attr:`~albedo_model.pca.PCAPart.residual_variance`)
as float32 (3n,) datasets ``residual_variance/<group>`` (``diffuseAlbedo``,
``specularAlbedo``, ``color``); files without them (AlbedoMM, BFM) give parts
whose residual variance is ``None``.

Writing produces float32 arrays, so ``read(write(m))`` is bit-identical for
models whose arrays are float32 (every model read from a file); float64 models
are rounded to float32 once. Writes are atomic.

This module imports only :mod:`albedo_model.errors`, :mod:`albedo_model.model`,
:mod:`albedo_model.pca`, :mod:`albedo_model.io.atomic` and :mod:`albedo_model.io.hdf5_layout`.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from typing import NamedTuple

import h5py
import numpy as np

from albedo_model.errors import InputError
from albedo_model.io.atomic import atomic_path
from albedo_model.io.hdf5_layout import (
    H5Reader,
    Representer,
    landmarks_to_json,
    open_h5,
    parse_landmarks_json,
    parse_tlms3d_text,
    read_pca_group,
    write_pca_group,
    write_text,
    write_version,
)
from albedo_model.model import MorphableModel
from albedo_model.pca import PCAPart
from albedo_model.uv_atlas import UVAtlas

__all__ = [
    "AlbedoPart", "open_h5", "h5_layout", "read_model_h5", "write_model_h5",
    "read_albedo_part", "write_albedo_part", "INFO_PATH", "SYMMETRY_PATH", "UV_PATH",
    "RESIDUAL_PATH",
]

INFO_PATH = "/metadata/mcmcfit/info"
SYMMETRY_PATH = "/metadata/mcmcfit/symmetry"
UV_PATH = "/metadata/mcmcfit/uv"
RESIDUAL_PATH = "/metadata/mcmcfit/residual_variance"
_INFO_FORMAT = "mcmcfit-model-info"
_ALBEDO_GROUPS = ("diffuseAlbedo", "specularAlbedo")


class AlbedoPart(NamedTuple):
    """The albedo half of an AlbedoMM model (an ``*_albedoPart.h5`` file).

    Attributes
    ----------
    vertices : (n, 3) float32 array
        Reference mesh points of the albedo representer (model frame, mm).
    triangles : (m, 3) int32 array
    diffuse, specular : PCAPart
        Dimension 3n, per-vertex interleaved linear sRGB.
    landmarks : dict of str to (3,) float64 arrays
    metadata : dict of str to str
    """

    vertices: np.ndarray
    triangles: np.ndarray
    diffuse: PCAPart
    specular: PCAPart
    landmarks: dict[str, np.ndarray]
    metadata: dict[str, str]


def _read_info(reader: H5Reader) -> dict | None:
    if not reader.has(INFO_PATH):
        return None
    try:
        info = json.loads(reader.text(INFO_PATH))
    except json.JSONDecodeError:
        raise reader.error(f"{INFO_PATH} is not JSON") from None
    if not isinstance(info, dict) or info.get("format") != _INFO_FORMAT:
        raise reader.error(f"{INFO_PATH} is not an mcmcfit model info record")
    if not isinstance(info.get("metadata", {}), dict):
        raise reader.error(f"{INFO_PATH} metadata must be a JSON object")
    return info


def h5_layout(reader: H5Reader) -> str:
    """``"momo"``, ``"albedomm"`` or ``"albedo-part"``; FormatError for anything else."""
    info = _read_info(reader)
    if info is not None and info.get("layout") in ("momo", "albedomm", "albedo-part"):
        return info["layout"]
    if all(reader.has(f"/{g}") for g in _ALBEDO_GROUPS):
        shape_mean = reader.shape_of("/shape/model/mean")
        points = reader.shape_of("/shape/representer/points")
        if shape_mean is None or points is None or shape_mean != (3 * points[-1],):
            return "albedo-part"
        return "albedomm"
    if reader.has("/shape") and reader.has("/color"):
        return "momo"
    if reader.has("/shape"):
        raise reader.error("model has no colour part (/color or /diffuseAlbedo + /specularAlbedo)")
    raise reader.error("not a morphable model (no /shape, /color or /diffuseAlbedo group)")


def _read_landmarks(reader: H5Reader) -> dict[str, np.ndarray]:
    if reader.has("/metadata/landmarks/json"):
        return parse_landmarks_json(reader.text("/metadata/landmarks/json"), reader.path)
    if reader.has("/metadata/landmarks/text"):
        return parse_tlms3d_text(reader.text("/metadata/landmarks/text"), reader.path)
    return {}


def _metadata(
    reader: H5Reader, info: dict | None, layout: str, colour_group: str
) -> dict[str, str]:
    """Return the stored metadata dict, or one describing a file written elsewhere."""
    if info is not None:
        return {str(k): str(v) for k, v in info.get("metadata", {}).items()}
    md = {"source_format": "AlbedoMM HDF5" if layout != "momo" else "scalismo MoMo HDF5"}
    cs = f"/{colour_group}/representer/colorspace"
    file_cs = reader.text(cs) if reader.has(cs) else "RGB"
    # AlbedoMM's README states its albedo is linear sRGB; the file only says "RGB".
    md["colour_space"] = "linear sRGB" if layout != "momo" else file_cs
    bt = f"/{colour_group}/modelinfo/build-time"
    if reader.has(bt):
        md["build_time"] = reader.text(bt).strip()
    return md


def _read_part(reader: H5Reader, group: str, mesh: Representer, info: dict | None) -> PCAPart:
    if not mesh.same_as(reader.representer(group)):
        raise reader.error(f"{group} representer differs from the reference mesh")
    part = read_pca_group(reader, group, len(mesh.points))
    exact = (info or {}).get("noise_variance", {}).get(group.strip("/"))
    if isinstance(exact, float) and np.float32(exact) == np.float32(part.noise_variance):
        part = PCAPart(part.mean, part.basis, part.variance, exact)
    residual_name = f"{RESIDUAL_PATH}/{group.strip('/')}"
    if reader.has(residual_name):
        residual = reader.array(residual_name, ndim=1)
        if residual.shape != (part.dim,) or np.any(residual < 0):
            raise reader.error(f"{residual_name} must hold {part.dim} non-negative values, got "
                               f"shape {residual.shape}")
        part = part.with_residual_variance(residual)
    return part


def read_model_h5(path: str | os.PathLike) -> MorphableModel:
    """Read a MoMo (BFM 2017) or AlbedoMM joint model file.

    Parameters
    ----------
    path : path-like

    Returns
    -------
    MorphableModel
        ``vertices`` (n, 3) float32 = shape representer points; parts as stored
        (float32); ``diffuse`` is ``/color`` or ``/diffuseAlbedo``.

    Raises
    ------
    FormatError
        Not HDF5, truncated, missing or malformed dataset, NaN, inconsistent
        shapes, or an albedo-part file (use :func:`read_albedo_part`).
    """
    with open_h5(path) as reader:
        layout = h5_layout(reader)
        if layout == "albedo-part":
            raise reader.error(
                "an AlbedoMM albedo part without a shape model; combine it with a BFM 2017 "
                "model first (mcmcfit model combine)"
            )
        info = _read_info(reader)
        mesh = reader.representer("/shape")
        colour = ("/color",) if layout == "momo" else ("/diffuseAlbedo", "/specularAlbedo")
        parts = {"shape": _read_part(reader, "/shape", mesh, info)}
        parts["diffuse"] = _read_part(reader, colour[0], mesh, info)
        if layout == "albedomm":
            parts["specular"] = _read_part(reader, colour[1], mesh, info)
        if reader.has("/expression"):
            parts["expression"] = _read_part(reader, "/expression", mesh, info)
        symmetry = None
        if reader.has(SYMMETRY_PATH):
            symmetry = reader.array(SYMMETRY_PATH, ndim=1, kind="iu")
        try:
            return MorphableModel(
                vertices=mesh.points, triangles=mesh.cells, **parts,
                shared_albedo=bool((info or {}).get("shared_albedo", True)),
                landmarks=_read_landmarks(reader), symmetry=symmetry,
                metadata=_metadata(reader, info, layout, colour[0].strip("/")),
                uv_atlas=read_uv_atlas(reader, UV_PATH))
        except InputError as exc:
            raise reader.error(str(exc)) from None


def read_albedo_part(path: str | os.PathLike) -> AlbedoPart:
    """Read the diffuse and specular albedo parts of an AlbedoMM file.

    Works on ``*_albedoPart.h5`` release files (whatever their ``/shape``
    holds), on albedo parts written by :func:`write_albedo_part`, and on joint
    AlbedoMM models (their albedo half).

    Returns
    -------
    AlbedoPart
        Reference mesh of the ``/diffuseAlbedo`` representer, both parts
        (float32), landmarks and metadata.
    """
    with open_h5(path) as reader:
        missing = [g for g in _ALBEDO_GROUPS if not reader.has(f"/{g}")]
        if missing:
            raise reader.error(f"not an AlbedoMM albedo model (missing /{missing[0]})")
        info = _read_info(reader)
        mesh = reader.representer("/diffuseAlbedo")
        diffuse = _read_part(reader, "/diffuseAlbedo", mesh, info)
        specular = _read_part(reader, "/specularAlbedo", mesh, info)
        if diffuse.rank != specular.rank:
            raise reader.error(
                f"diffuse and specular albedo ranks differ ({diffuse.rank} vs {specular.rank}); "
                "AlbedoMM shares one coefficient vector"
            )
        return AlbedoPart(
            mesh.points, mesh.cells, diffuse, specular, _read_landmarks(reader),
            _metadata(reader, info, "albedo-part", "diffuseAlbedo"),
        )


# -- writing -----------------------------------------------------------------

def read_uv_atlas(reader: H5Reader, group: str) -> UVAtlas | None:
    """Read the UV atlas stored under ``group`` (``coordinates``, ``triangles``), or None."""
    if not reader.has(group):
        return None
    uv = reader.array(f"{group}/coordinates", ndim=2)
    tri = reader.array(f"{group}/triangles", ndim=2, kind="iu")
    try:
        return UVAtlas(uv, tri)
    except InputError as exc:
        raise reader.error(f"{group}: {exc}") from None


def write_uv_atlas(group: h5py.Group, atlas: UVAtlas) -> None:
    """Write ``atlas`` into ``group``: float32 ``coordinates`` (t, 2), int32 ``triangles``."""
    group.create_dataset("coordinates", data=atlas.uv.astype(np.float32))
    group.create_dataset("triangles", data=atlas.uv_triangles.astype(np.int32))


def _write_catalog(h5: h5py.File, groups: list[str]) -> None:
    cat = h5.create_group("catalog")
    top = cat.create_group("MorphableModel")
    write_text(top, "modelPath", "/")
    write_text(top, "modelType", "CUSTOM_MODEL")
    for group in groups:
        entry = cat.create_group(f"MorphableModel.{group}")
        kind = "POLYGON_MESH_MODEL" if group == "shape" else "POLYGON_MESH_DATA_MODEL"
        write_text(entry, "modelType", kind)
        write_text(entry, "modelPath", f"/{group}")


def _write_file(
    path: str | os.PathLike,
    vertices: np.ndarray,
    triangles: np.ndarray,
    parts: dict[str, PCAPart],
    *,
    layout: str,
    landmarks: Mapping[str, np.ndarray],
    metadata: Mapping[str, str],
    shared_albedo: bool,
    symmetry: np.ndarray | None = None,
    uv_atlas: UVAtlas | None = None,
) -> None:
    info = {
        "format": _INFO_FORMAT, "version": 1, "layout": layout,
        "shared_albedo": bool(shared_albedo),
        "metadata": {str(k): str(v) for k, v in metadata.items()},
        "noise_variance": {g: float(p.noise_variance) for g, p in parts.items()},
    }
    with atomic_path(path) as tmp:
        with h5py.File(tmp, "w") as h5:
            write_version(h5)
            _write_catalog(h5, list(parts))
            for group, part in parts.items():
                colour = group in ("color", *_ALBEDO_GROUPS)
                write_pca_group(h5, group, part, vertices, triangles, colorspace=colour)
            meta = h5.create_group("metadata")
            write_text(meta.create_group("landmarks"), "json", landmarks_to_json(landmarks))
            ours = meta.create_group("mcmcfit")
            write_text(ours, "info", json.dumps(info))
            if symmetry is not None:
                ours.create_dataset("symmetry", data=np.asarray(symmetry, np.int32))
            if uv_atlas is not None:
                write_uv_atlas(ours.create_group("uv"), uv_atlas)
            for group, part in parts.items():
                if part.residual_variance is not None:
                    ours.require_group("residual_variance").create_dataset(
                        group, data=np.asarray(part.residual_variance, np.float32))


def write_model_h5(
    model: MorphableModel, path: str | os.PathLike, *, layout: str | None = None
) -> None:
    """Write ``model`` in the MoMo or AlbedoMM joint layout (atomically).

    Parameters
    ----------
    model : MorphableModel
    path : path-like
    layout : {"momo", "albedomm"}, optional
        Default: ``"albedomm"`` when the model has a specular part, else
        ``"momo"`` (diffuse written as ``/color``).
    """
    layout = layout or ("albedomm" if model.specular is not None else "momo")
    if layout == "momo" and model.specular is not None:
        raise InputError("a model with specular albedo needs the AlbedoMM layout")
    if layout == "albedomm" and model.specular is None:
        raise InputError("the AlbedoMM layout needs a specular albedo part")
    if layout not in ("momo", "albedomm"):
        raise InputError(f"unknown model layout {layout!r}")
    parts = {"shape": model.shape}
    if layout == "momo":
        parts["color"] = model.diffuse
    else:
        parts.update(diffuseAlbedo=model.diffuse, specularAlbedo=model.specular)
    if model.expression is not None:
        parts["expression"] = model.expression
    _write_file(
        path, model.vertices, model.triangles, parts, layout=layout, landmarks=model.landmarks,
        metadata=model.metadata, shared_albedo=model.shared_albedo, symmetry=model.symmetry,
        uv_atlas=model.uv_atlas)


def write_albedo_part(
    part: AlbedoPart, path: str | os.PathLike, *, shape_placeholder: bool = True
) -> None:
    """Write an albedo part (``*_albedoPart.h5`` layout), atomically.

    Parameters
    ----------
    part : AlbedoPart
    path : path-like
    shape_placeholder : bool
        Add a ``/shape`` group (mean = reference mesh, one zero-variance
        component) so that AlbedoMM's reader, which requires a shape group, can
        open the file. Our readers ignore it.
    """
    v = np.asarray(part.vertices)
    n3 = 3 * len(v)
    for name in ("diffuse", "specular"):
        dim = getattr(part, name).dim
        if dim != n3:
            raise InputError(f"{name} albedo has dimension {dim}, expected {n3}")
    if part.diffuse.rank != part.specular.rank:
        raise InputError("diffuse and specular albedo must have equal ranks")
    parts: dict[str, PCAPart] = {}
    if shape_placeholder:
        basis = np.zeros((n3, 1), np.float32)
        basis[0, 0] = 1.0
        parts["shape"] = PCAPart(v.reshape(-1).astype(np.float32), basis, np.zeros(1, np.float32))
    parts.update(diffuseAlbedo=part.diffuse, specularAlbedo=part.specular)
    _write_file(
        path, v, part.triangles, parts, layout="albedo-part", landmarks=part.landmarks,
        metadata=part.metadata, shared_albedo=True,
    )
