"""Model specs on the command line: a file path, ``default`` or ``default-face`` (built on first use).

``default`` is the built-in synthetic model (a whole head); ``default-face`` is
its face crop (forehead to chin, ear to ear in front of the ears), built from
it by cropping the first time it is asked for.

This module imports :mod:`albedo_model.io.model_files` and :mod:`albedo_model.model`;
:mod:`pipeline.synthetic.default_model` is imported when ``default`` is resolved and
:mod:`pipeline.synthetic.default_face_model` when ``default-face`` is.
"""

from __future__ import annotations

from pathlib import Path

from albedo_model.io.model_files import (
    DEFAULT_FACE_MODEL,
    DEFAULT_MODEL,
    load_model,
    resolve_model_path,
)
from albedo_model.model import MorphableModel

__all__ = ["load_model_spec", "resolve_model"]


def resolve_model(spec: str, *, progress: bool = True) -> Path:
    """Return the model file for ``spec``; a built-in model is built first if needed."""
    if str(spec) == DEFAULT_MODEL:
        from pipeline.synthetic.default_model import ensure_default_model

        return ensure_default_model(progress=progress)
    if str(spec) == DEFAULT_FACE_MODEL:
        from pipeline.synthetic.default_face_model import ensure_default_face_model

        return ensure_default_face_model(progress=progress)
    return resolve_model_path(spec)


def load_model_spec(spec: str, *, progress: bool = True) -> MorphableModel:
    """Load the model named by ``spec`` (path, ``"default"`` or ``"default-face"``)."""
    return load_model(resolve_model(spec, progress=progress))
