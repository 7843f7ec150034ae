"""Atomic file writing: write to a temporary sibling, then rename.

A failed write never leaves a partial file at the target path, and never
clobbers an existing file with garbage.

This module imports nothing from the project.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

__all__ = ["atomic_path"]


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success.

    Parameters
    ----------
    path : path-like
        Final destination. Its parent folder must exist.
    suffix : str, optional
        Suffix of the temporary file (default: that of ``path``, so that
        libraries choosing a format by extension still work).

    Examples
    --------
    >>> with atomic_path("out.h5") as tmp:          # doctest: +SKIP
    ...     write_file(tmp)
    """
    final = Path(path)
    if not final.parent.exists():
        raise FileNotFoundError(f"{final.parent}: output folder does not exist")
    fd, name = tempfile.mkstemp(
        prefix=f".{final.name}.", suffix=final.suffix if suffix is None else suffix,
        dir=final.parent,
    )
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        os.replace(tmp, final)
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
