"""Where the built-in default model lives (a cached file; building it is ``pipeline``'s job).

The default model is built deterministically by
:func:`pipeline.synthetic.default_model.ensure_default_model` on first use and cached at
:func:`default_model_path`. This module only knows the location, so that the
lowest package can resolve ``"default"`` without importing the builder.

This module imports only :mod:`albedo_model.errors`.
"""

from __future__ import annotations

import os
from pathlib import Path

from albedo_model.errors import InputError

__all__ = ["BUILD_VERSION", "cache_dir", "cached_model_path", "default_model_path"]

#: Bumped whenever the file layout of the default model changes.
BUILD_VERSION = 1
_PREFIX = f"default-albedo-model-v{BUILD_VERSION}-"


def cache_dir() -> Path:
    """``$MCMCFIT_CACHE``, else ``$XDG_CACHE_HOME/mcmcfit``, else ``~/.cache/mcmcfit``."""
    env = os.environ.get("MCMCFIT_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "mcmcfit"


def cached_model_path(prefix: str, spec: str, fingerprint: str | None = None, *,
                      must_exist: bool = True) -> Path:
    """Return the cached file of a built-in model (``<prefix><fingerprint>.h5`` in :func:`cache_dir`).

    Parameters
    ----------
    prefix : str
        File-name prefix of that built-in model.
    spec : str
        Its name on the command line (for the error).
    fingerprint : str, optional
        Identifies the builder's code and settings (``pipeline`` computes it), so
        that a changed builder never serves a stale cache. Without it, the most
        recently built file with ``prefix`` is returned.
    must_exist : bool
        Raise :class:`InputError` when no such file has been built yet (the
        ``mcmcfit`` commands build it on first use).
    """
    folder = cache_dir()
    if fingerprint is not None:
        path = folder / f"{prefix}{fingerprint}.h5"
    else:
        built = sorted(folder.glob(f"{prefix}*.h5"), key=lambda p: p.stat().st_mtime)
        path = built[-1] if built else folder / f"{prefix}unbuilt.h5"
    if must_exist and not path.is_file():
        raise InputError(f"{path}: the built-in {spec} model has not been built yet "
                         f"(any `mcmcfit ... {spec}` command builds it)")
    return path


def default_model_path(fingerprint: str | None = None, *, must_exist: bool = True) -> Path:
    """Return the cached default model file (see :func:`cached_model_path`)."""
    return cached_model_path(_PREFIX, "default", fingerprint, must_exist=must_exist)
