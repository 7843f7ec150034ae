"""The built-in ``default-face`` model: the default model cropped to its face, cached.

The default model (:mod:`pipeline.synthetic.default_model`) is a whole head.
Its face crop keeps the vertices of :func:`pipeline.synthetic.face_region.face_region`
on the template head (forehead to chin, ear to ear in front of the ears, like
BFM 2017's ``face12`` beside its full head) and is the exact marginal of the
default model there (:func:`albedo_model.model_crop.crop_model`). It is built
from the cached default model file on first use, deterministically, and cached
beside it at :func:`albedo_model.io.model_files.default_face_model_path`, keyed
by the default model's fingerprint and the crop's code.

This module imports :mod:`albedo_model` (``default_model``, ``errors``, ``model``, ``uv_atlas``,
``model_crop``, ``io.model_files``, ``io.momo_h5``) and
:mod:`pipeline.synthetic.default_model`; :mod:`pipeline.synthetic.face_region`
and :mod:`pipeline.synthetic.head.template_head` are imported when the crop is
built.
"""

from __future__ import annotations

import dataclasses
import hashlib
import sys
import time
from pathlib import Path

import numpy as np

from albedo_model.default_model import BUILD_VERSION
from albedo_model.errors import InputError
from albedo_model.io.model_files import DEFAULT_FACE_MODEL, default_face_model_path, file_sha256
from albedo_model.io.momo_h5 import read_model_h5, write_model_h5
from albedo_model.model import MorphableModel
from albedo_model.model_crop import crop_model
from albedo_model.uv_atlas import compute_uv_atlas
from pipeline.synthetic.default_model import default_model_fingerprint, ensure_default_model

__all__ = ["build_default_face_model", "default_face_model_fingerprint",
           "ensure_default_face_model"]

#: Sources whose code determines the crop (besides the default model's own builder).
_CROP_SOURCES = ("pipeline/synthetic/default_face_model.py", "pipeline/synthetic/face_region.py",
                 "albedo_model/model_crop.py", "albedo_model/uv_atlas.py")


def build_default_face_model(full: MorphableModel, *, source: str = "") -> MorphableModel:
    """Crop the default model ``full`` to the face region of the template head.

    Parameters
    ----------
    full : MorphableModel
        The default model (its vertices are the template head's, in order).
    source : str
        Names the cropped file (recorded in the metadata).

    Returns
    -------
    MorphableModel
        Shared albedo coefficients, symmetry map and the landmarks on the face,
        metadata of the default model plus ``crop`` (what and how) and a new
        ``description``.

    Raises
    ------
    InputError
        ``full`` is not on the template head's vertices.
    """
    from pipeline.synthetic.face_region import FACE_REGION_RULE, face_region
    from pipeline.synthetic.head.template_head import build_template_head

    head = build_template_head()
    if full.n_vertices != head.n_vertices or not np.allclose(
        full.vertices, head.vertices, atol=1e-3
    ):
        raise InputError("the model's reference mesh is not the template head; cannot find its "
                         "face region")
    model = crop_model(full, face_region(head), unpaired="error", source=source,
                       region=FACE_REGION_RULE)
    description = full.metadata.get("description", "mcmcfit built-in model")
    metadata = {**model.metadata, "description": f"{description}; face crop (no scalp, ears "
                                                 "or neck), the exact marginal of the full head"}
    # a UV atlas of its own: the head's atlas restricted to the face fills an eighth of a texture
    return dataclasses.replace(model, metadata=metadata,
                               uv_atlas=compute_uv_atlas(model.vertices, model.triangles))


def default_face_model_fingerprint() -> str:
    """Hash of the default model's fingerprint and the crop's code (names the cached file)."""
    h = hashlib.sha256(repr((BUILD_VERSION, default_model_fingerprint())).encode())
    root = Path(__file__).resolve().parents[2]  # the folder holding pipeline/ and albedo_model/
    for name in _CROP_SOURCES:
        h.update((root / name).read_bytes())
    return h.hexdigest()[:16]


def ensure_default_face_model(*, progress: bool = True) -> Path:
    """Path of the cached ``default-face`` model, building the default model and the crop if needed.

    The file is written atomically (concurrent first uses write identical files).
    """
    path = default_face_model_path(default_face_model_fingerprint(), must_exist=False)
    if path.is_file():
        return path
    full_path = ensure_default_model(progress=progress)
    start = time.perf_counter()
    full = read_model_h5(full_path)
    source = f"the default model, file {full_path.name} (sha256 {file_sha256(full_path)})"
    model = build_default_face_model(full, source=source)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_model_h5(model, path)
    if progress:
        print(f"built the {DEFAULT_FACE_MODEL} model in {time.perf_counter() - start:.1f} s "
              f"({model.n_vertices} of {full.n_vertices} vertices): {path}", file=sys.stderr)
    return path
