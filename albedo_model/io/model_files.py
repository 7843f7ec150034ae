"""Finding, recognising, loading and combining model files.

``load_model`` dispatches on the file's content, not its name: HDF5 with
``/color`` (scalismo MoMo, BFM 2017) or with ``/diffuseAlbedo`` +
``/specularAlbedo`` (AlbedoMM joint model). Albedo-part files and the FLAME
npz are recognised and refused with a message saying what to do instead.
``"default"`` names the built-in model (a whole head), resolved lazily through
``albedo_model.default_model.default_model_path()``; ``"default-face"`` names its
face crop (no scalp, ears or neck; see :mod:`pipeline.synthetic.default_face_model`),
cached beside it and located by :func:`default_face_model_path`.

This module imports only :mod:`albedo_model.default_model`, :mod:`albedo_model.errors`,
:mod:`albedo_model.model` and :mod:`albedo_model.io.momo_h5`.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import h5py
import numpy as np

from albedo_model.default_model import BUILD_VERSION, cached_model_path, default_model_path
from albedo_model.errors import FormatError, InputError
from albedo_model.io.momo_h5 import (
    AlbedoPart,
    h5_layout,
    open_h5,
    read_albedo_part,
    read_model_h5,
    write_model_h5,
)
from albedo_model.model import MorphableModel

__all__ = [
    "BUILTIN_MODELS",
    "DEFAULT_FACE_MODEL",
    "DEFAULT_MODEL",
    "combine_model_files",
    "combine_shape_albedo",
    "default_face_model_path",
    "file_sha256",
    "load_model",
    "model_file_kind",
    "resolve_model_path",
]

#: The spelling of the built-in model on the command line.
DEFAULT_MODEL = "default"
#: The spelling of the built-in model's face crop on the command line.
DEFAULT_FACE_MODEL = "default-face"
#: Model specs that name a built-in (cached, built on first use) model rather than a file.
BUILTIN_MODELS = (DEFAULT_MODEL, DEFAULT_FACE_MODEL)
_FACE_PREFIX = f"default-face-albedo-model-v{BUILD_VERSION}-"


def default_face_model_path(fingerprint: str | None = None, *, must_exist: bool = True) -> Path:
    """Return the cached face crop of the default model (``"default-face"``).

    Parameters
    ----------
    fingerprint : str, optional
        Identifies the default model and the crop's code (``pipeline`` computes
        it). Without it, the most recently built face crop in the cache.
    must_exist : bool
        Raise :class:`InputError` when no such file has been built yet.
    """
    return cached_model_path(_FACE_PREFIX, DEFAULT_FACE_MODEL, fingerprint, must_exist=must_exist)


def file_sha256(path: str | os.PathLike) -> str:
    """Hex SHA-256 of a file's bytes (read in 1 MiB blocks)."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def resolve_model_path(spec: str | os.PathLike) -> Path:
    """Return the model file named by ``spec``: a path, ``"default"`` or ``"default-face"``.

    Raises
    ------
    InputError
        The file does not exist, or the built-in model has not been built yet
        (``mcmcfit.jobs.model_spec.resolve_model`` builds it).
    """
    if isinstance(spec, str) and spec == DEFAULT_MODEL:
        path = default_model_path()
    elif isinstance(spec, str) and spec == DEFAULT_FACE_MODEL:
        path = default_face_model_path()
    else:
        path = Path(spec).expanduser()
    if not path.is_file():
        raise InputError(f"{path}: model file not found")
    return path


def model_file_kind(path: str | os.PathLike) -> str:
    """``"momo"``, ``"albedomm"``, ``"albedo-part"`` or ``"flame-npz"``, from the content.

    Raises
    ------
    FormatError
        Neither HDF5 nor an npz archive, or an HDF5 file of another layout.
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: file not found")
    with p.open("rb") as fh:
        head = fh.read(4)
    if head in (b"PK\x03\x04", b"PK\x05\x06"):
        return "flame-npz"
    if head[:1] == b"\x80":
        raise FormatError(p, "a Python pickle; needs pickle; refusing to unpickle")
    if not h5py.is_hdf5(p):
        raise FormatError(p, "neither an HDF5 model nor an npz archive")
    with open_h5(p) as reader:
        return h5_layout(reader)


def load_model(path_or_spec: str | os.PathLike) -> MorphableModel:
    """Load a complete morphable model (MoMo or AlbedoMM joint file, or a built-in model).

    Parameters
    ----------
    path_or_spec : path-like, "default" or "default-face"

    Returns
    -------
    MorphableModel

    Raises
    ------
    FormatError
        Unreadable or malformed file, or a file that holds only an albedo model
        (an albedo part or the FLAME npz).
    InputError
        Missing file or no built-in model.
    """
    path = resolve_model_path(path_or_spec)
    kind = model_file_kind(path)
    if kind == "flame-npz":
        raise FormatError(
            path, "a texture-space FLAME albedo model without a mesh; it is not a complete model"
        )
    return read_model_h5(path)


def combine_shape_albedo(
    shape: MorphableModel, albedo: AlbedoPart, *, metadata: dict[str, str] | None = None
) -> MorphableModel:
    """Build the AlbedoMM joint model: ``shape``'s geometry and landmarks + both albedo parts.

    This is what AlbedoMM's ``AlbedoModelBuilder`` does with BFM 2017 and an
    ``albedoPart`` file. Diffuse and specular share their coefficients.

    Parameters
    ----------
    shape : MorphableModel
        Provides reference mesh, shape, expression, landmarks and symmetry.
    albedo : AlbedoPart
        Must have the same vertex count and identical triangles.
    metadata : dict, optional
        Added to (and overriding) the merged metadata of both inputs.

    Raises
    ------
    InputError
        The topologies differ (vertex count or cells).
    """
    if len(albedo.vertices) != shape.n_vertices:
        raise InputError(
            f"topology differs: {len(albedo.vertices)} albedo vertices, "
            f"{shape.n_vertices} shape vertices"
        )
    if albedo.triangles.shape != shape.triangles.shape or not np.array_equal(
        albedo.triangles, shape.triangles
    ):
        raise InputError(
            f"topology differs: the triangle lists are not identical ({len(albedo.triangles)} "
            f"albedo, {shape.n_triangles} shape triangles)"
        )
    merged = {**shape.metadata, **albedo.metadata, **(metadata or {})}
    return MorphableModel(
        vertices=shape.vertices, triangles=shape.triangles, shape=shape.shape,
        diffuse=albedo.diffuse, expression=shape.expression, specular=albedo.specular,
        shared_albedo=True, landmarks=shape.landmarks, symmetry=shape.symmetry, metadata=merged,
    )


def combine_model_files(
    shape_path: str | os.PathLike, albedo_path: str | os.PathLike, out_path: str | os.PathLike
) -> MorphableModel:
    """Combine a BFM-style model file and an albedo-part file; write the joint AlbedoMM file.

    The output is written atomically; on any error nothing is written.

    Returns
    -------
    MorphableModel
        The model written to ``out_path``.
    """
    shape_path, albedo_path = Path(shape_path), Path(albedo_path)
    if model_file_kind(albedo_path) == "flame-npz":
        raise FormatError(albedo_path, "a FLAME texture-space albedo cannot be combined with a "
                                       "per-vertex shape model")
    shape = read_model_h5(shape_path)
    albedo = read_albedo_part(albedo_path)
    provenance = {
        "source_format": "AlbedoMM HDF5",
        "shape_source": shape_path.name, "shape_sha256": file_sha256(shape_path),
        "albedo_source": albedo_path.name, "albedo_sha256": file_sha256(albedo_path),
    }
    try:
        model = combine_shape_albedo(shape, albedo, metadata=provenance)
    except InputError as exc:
        raise FormatError(albedo_path, f"{exc} (shape model {shape_path.name})") from None
    write_model_h5(model, out_path, layout="albedomm")
    return model
