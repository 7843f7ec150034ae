"""Output folders of a batch, derived safely from input paths.

Every image's results go to ``OUT/<relative path without extension>/``. The
relative path comes from the user (a walked folder, or lines of a list file),
so it is sanitised before it is joined to OUT: ``..`` components, absolute
anchors and empty or dot components never leave OUT.

A result folder is *complete* when it holds ``summary.json`` (the fit job
writes it last and renames the whole folder into place, so its presence means
every output is there).

This module imports only the standard library.
"""

from __future__ import annotations

import os
import re
import shutil
from pathlib import Path, PurePosixPath, PureWindowsPath

__all__ = ["COMPLETE_MARKER", "TEMP_PREFIXES", "safe_relative", "result_dir", "is_complete",
           "stale_temp_dirs", "remove_stale_temp_dirs"]

#: File whose presence marks a finished result folder.
COMPLETE_MARKER = "summary.json"

#: A fit job writes into ``.<name>.partial-*`` and moves a replaced folder to
#: ``.<name>.old-*`` (:func:`mcmcfit.jobs.fit_job.atomic_folder`); a killed job leaves them.
TEMP_PREFIXES = ("partial-", "old-")

_UNSAFE_CHARS = re.compile(r"[\x00-\x1f<>:\"|?*\\]")


def _clean_component(part: str) -> str:
    part = _UNSAFE_CHARS.sub("_", part).strip()
    if part in ("", "."):
        return ""
    if part == "..":
        return "_up"
    # a leading dot would hide the folder and could collide with temporary siblings
    return "_" + part[1:] if part.startswith(".") else part


def safe_relative(path: str | os.PathLike) -> PurePosixPath:
    r"""Return a relative POSIX path for ``path`` that cannot leave the folder it is joined to.

    The extension of the last component is dropped. ``..`` becomes ``_up``
    (so ``../../etc/x.jpg`` gives ``_up/_up/etc/x``), an absolute path's anchor
    becomes ``_abs``, empty and ``.`` components are dropped, control and
    reserved characters become ``_``, and a leading dot becomes ``_``.

    Parameters
    ----------
    path : str or path-like
        An input path as given, relative (to the input root) or absolute;
        ``/`` and ``\`` both separate components.

    Returns
    -------
    PurePosixPath
        Non-empty, relative, without ``..`` components.

    Raises
    ------
    ValueError
        Nothing usable is left of ``path`` (for example ``".."`` or ``"/"``).
    """
    text = os.fspath(path)
    win = PureWindowsPath(text)
    parts = list(win.parts)
    prefix: list[str] = []
    if win.anchor:
        prefix = ["_abs"]
        parts = parts[1:]
    cleaned = [_clean_component(p) for p in parts]
    cleaned = [p for p in cleaned if p]
    if not cleaned or cleaned[-1] == "_up":
        raise ValueError(f"no file name in input path {text!r}")
    stem = PurePosixPath(cleaned[-1]).stem if "." in cleaned[-1][1:] else cleaned[-1]
    cleaned[-1] = _clean_component(stem) or "_"
    return PurePosixPath(*prefix, *cleaned)


def result_dir(out_root: str | os.PathLike, relative: PurePosixPath) -> Path:
    """``out_root / relative``, checked to stay inside ``out_root``.

    Raises
    ------
    ValueError
        ``relative`` is absolute or has a ``..`` component (never the case for
        the output of :func:`safe_relative`).
    """
    rel = PurePosixPath(relative)
    if rel.is_absolute() or ".." in rel.parts or not rel.parts:
        raise ValueError(f"unsafe relative output path {str(rel)!r}")
    root = Path(out_root)
    out = root.joinpath(*rel.parts)
    if os.path.commonpath([os.path.abspath(root), os.path.abspath(out)]) != os.path.abspath(root):
        raise ValueError(f"output path {out} leaves {root}")
    return out


def is_complete(folder: str | os.PathLike) -> bool:
    """Return whether ``folder`` is a finished result folder (it holds ``summary.json``)."""
    return (Path(folder) / COMPLETE_MARKER).is_file()


def stale_temp_dirs(folder: str | os.PathLike) -> list[Path]:
    """Temporary siblings of ``folder`` left by an interrupted fit job.

    They are hidden folders in the same parent named ``.<folder name>.`` followed
    by one of :data:`TEMP_PREFIXES`.
    """
    target = Path(folder)
    parent = target.parent
    if not parent.is_dir():
        return []
    prefixes = tuple(f".{target.name}.{p}" for p in TEMP_PREFIXES)
    return sorted(p for p in parent.iterdir() if p.is_dir() and p.name.startswith(prefixes))


def remove_stale_temp_dirs(folder: str | os.PathLike) -> list[Path]:
    """Delete :func:`stale_temp_dirs` of ``folder``; return what was removed.

    Call only when no job for ``folder`` is running (the batch does it before
    submitting the image's task).
    """
    removed = stale_temp_dirs(folder)
    for p in removed:
        shutil.rmtree(p, ignore_errors=True)
    return removed
