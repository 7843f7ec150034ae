"""Model specs on the command line: a file path, or ``default`` (built on first use).

This module imports :mod:`albedo_model.io.model_files` and :mod:`albedo_model.model`;
:mod:`pipeline.synthetic.default_model` is imported when ``default`` is resolved.
"""

from __future__ import annotations

from pathlib import Path

from albedo_model.io.model_files import DEFAULT_MODEL, load_model, resolve_model_path
from albedo_model.model import MorphableModel

__all__ = ["resolve_model", "load_model_spec"]


def resolve_model(spec: str, *, progress: bool = True) -> Path:
    """Return the model file for ``spec``; ``"default"`` builds the built-in model if needed."""
    if str(spec) == DEFAULT_MODEL:
        from pipeline.synthetic.default_model import ensure_default_model

        return ensure_default_model(progress=progress)
    return resolve_model_path(spec)


def load_model_spec(spec: str, *, progress: bool = True) -> MorphableModel:
    """Load the model named by ``spec`` (path or ``"default"``)."""
    return load_model(resolve_model(spec, progress=progress))
