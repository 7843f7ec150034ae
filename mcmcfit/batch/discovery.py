"""The images of a batch and the landmark file of each.

INPUT is a folder, walked recursively for ``.jpg`` / ``.jpeg`` / ``.png``
files (hidden files and folders are ignored, and so is the output folder when
it lies inside INPUT), or a text file listing one image per line (blank lines
and lines starting with ``#`` are ignored; relative entries are relative to the
list file's folder).

Landmarks, first match wins:

* ``landmarks_dir``: a parallel tree, ``DIR/<relative path without
  extension>.tlms`` (or ``.pts``);
* ``landmarks_glob``: a pattern with the placeholders ``{stem}`` (file name
  without extension), ``{name}`` (file name), ``{rel}`` (relative path without
  extension) and ``{parent}`` (the relative folder), relative to the image's
  folder unless absolute; glob wildcards are allowed and must match exactly one
  file (``--landmarks-glob '../lm/{stem}*.pts'``);
* otherwise beside the image: ``<stem>.tlms``, then ``<stem>.pts``.

With ``--group-by person`` (:func:`group_by_person`) the images of one person
are fitted jointly: a person is the image's folder relative to INPUT (LFW:
``Name/Name_0001.jpg``), or for an image at the top of INPUT its stem without
a trailing ``_<number>`` (``Name_0001.jpg``).

This module imports only :mod:`mcmcfit.batch` modules and the standard library.
"""

from __future__ import annotations

import glob
import os
import re
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from mcmcfit.batch.out_paths import safe_relative

__all__ = ["IMAGE_SUFFIXES", "LANDMARK_SUFFIXES", "BatchItem", "PersonGroup", "Skipped",
           "discover", "find_landmarks", "group_by_person", "list_images", "person_of"]

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png")
LANDMARK_SUFFIXES = (".tlms", ".pts")


@dataclass(frozen=True)
class BatchItem:
    """One image of a batch.

    Attributes
    ----------
    image : Path
        Absolute path of the image.
    source : str
        The image as the user named it: the path relative to the input folder
        (POSIX separators), or the list file's line.
    relative : PurePosixPath
        Safe relative output path without extension (``Name/Name_0001``).
    landmarks : Path or None
        The landmark file, None when the image is fitted with a face box.
    """

    image: Path
    source: str
    relative: PurePosixPath
    landmarks: Path | None


@dataclass(frozen=True)
class Skipped:
    """An input that will not be fitted, and why."""

    source: str
    relative: str
    reason: str


def _is_hidden(rel: Path) -> bool:
    return any(part.startswith(".") for part in rel.parts)


def _walk_folder(root: Path, exclude: list[Path]) -> list[tuple[Path, str]]:
    excluded = [os.path.abspath(e) for e in exclude]
    found = []
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = sorted(d for d in dirnames if not d.startswith(".")
                             and os.path.abspath(os.path.join(dirpath, d)) not in excluded)
        for name in sorted(filenames):
            if name.startswith(".") or os.path.splitext(name)[1].lower() not in IMAGE_SUFFIXES:
                continue
            path = Path(dirpath) / name
            rel = path.relative_to(root)
            if not _is_hidden(rel):
                found.append((path.absolute(), rel.as_posix()))
    return sorted(found, key=lambda pair: pair[1])


def _read_list(list_file: Path) -> list[tuple[Path, str]]:
    base = list_file.parent
    out = []
    for line in list_file.read_text(encoding="utf-8-sig").splitlines():
        entry = line.strip()
        if not entry or entry.startswith("#"):
            continue
        path = Path(entry)
        if path.is_absolute():
            try:
                source = path.relative_to(base.absolute()).as_posix()
            except ValueError:
                source = entry
        else:
            source = os.path.normpath(entry).replace(os.sep, "/")
            path = base / entry
        out.append((Path(os.path.abspath(path)), source))
    return out


def list_images(input_path: str | os.PathLike, *, exclude: list[Path] | None = None
                ) -> list[tuple[Path, str]]:
    """List the images of a batch as ``(absolute path, source name)`` pairs.

    Parameters
    ----------
    input_path : path-like
        A folder (walked recursively, sorted) or a text file with one image per line.
    exclude : list of Path, optional
        Folders not to walk into (the batch's output folder).

    Raises
    ------
    FileNotFoundError
        ``input_path`` does not exist.
    """
    p = Path(input_path)
    if p.is_dir():
        return _walk_folder(p, exclude or [])
    if p.is_file():
        return _read_list(p)
    raise FileNotFoundError(2, "No such file or directory", str(p))


def _glob_landmarks(image: Path, rel: PurePosixPath, pattern: str) -> list[Path]:
    parent = rel.parent.as_posix() if str(rel.parent) != "." else ""
    filled = pattern.format(stem=glob.escape(image.stem), name=glob.escape(image.name),
                            rel=glob.escape(rel.as_posix()), parent=glob.escape(parent))
    full = filled if os.path.isabs(filled) else os.path.join(glob.escape(str(image.parent)), filled)
    return sorted(Path(m) for m in glob.glob(full) if os.path.isfile(m))


def find_landmarks(image: Path, relative: PurePosixPath, *,
                   landmarks_dir: str | os.PathLike | None = None,
                   landmarks_glob: str | None = None) -> tuple[Path | None, str, bool]:
    """Find the landmark file of one image, or None with the reason it was not found.

    Parameters
    ----------
    image : Path
        Absolute image path.
    relative : PurePosixPath
        The image's relative path without extension (for the parallel tree).
    landmarks_dir : path-like, optional
    landmarks_glob : str, optional
        See the module docstring.

    Returns
    -------
    (Path or None, str, bool)
        The file, or None and a sentence saying where it was looked for; the
        flag is True when the lookup was ambiguous (several files match), which
        never falls back to a face box.
    """
    if landmarks_dir is not None:
        base = Path(landmarks_dir).joinpath(*relative.parts)
        candidates = [base.with_name(base.name + s) for s in LANDMARK_SUFFIXES]
    elif landmarks_glob is not None:
        matches = _glob_landmarks(image, relative, landmarks_glob)
        if len(matches) > 1:
            names = ", ".join(m.name for m in matches[:3])
            return (None, f"landmark pattern {landmarks_glob!r} matches {len(matches)} files "
                    f"({names})", True)
        if not matches:
            return None, f"no landmark file matches {landmarks_glob!r}", False
        return matches[0], "", False
    else:
        candidates = [image.with_suffix(s) for s in LANDMARK_SUFFIXES]
    for c in candidates:
        if c.is_file():
            return c, "", False
    return (None, "no landmark file (looked for " + ", ".join(str(c) for c in candidates) + ")",
            False)


def discover(input_path: str | os.PathLike, *, exclude: list[Path] | None = None,
             landmarks_dir: str | os.PathLike | None = None, landmarks_glob: str | None = None,
             allow_face_box: bool = False) -> tuple[list[BatchItem], list[Skipped]]:
    """Find the images to fit and those skipped (no landmarks, unusable name, clashing output).

    Parameters
    ----------
    input_path : path-like
        Folder or list file (see :func:`list_images`).
    exclude : list of Path, optional
        Folders not to walk into.
    landmarks_dir, landmarks_glob : optional
        Where landmarks are (see the module docstring); at most one.
    allow_face_box : bool
        Images without landmarks are fitted with a face box (their ``landmarks``
        is None) instead of being skipped.

    Returns
    -------
    (list of BatchItem, list of Skipped)
        In input order.
    """
    if landmarks_dir is not None and landmarks_glob is not None:
        raise ValueError("give at most one of landmarks_dir and landmarks_glob")
    items: list[BatchItem] = []
    skipped: list[Skipped] = []
    seen: dict[PurePosixPath, str] = {}
    for image, source in list_images(input_path, exclude=exclude):
        try:
            rel = safe_relative(source)
        except ValueError as exc:
            skipped.append(Skipped(source, "", str(exc)))
            continue
        if rel in seen:
            skipped.append(Skipped(source, str(rel), f"same output folder as {seen[rel]}"))
            continue
        seen[rel] = source
        landmarks, why, ambiguous = find_landmarks(image, rel, landmarks_dir=landmarks_dir,
                                                   landmarks_glob=landmarks_glob)
        if ambiguous:
            skipped.append(Skipped(source, str(rel), why))
            continue
        if landmarks is None and not allow_face_box:
            skipped.append(Skipped(source, str(rel),
                                   f"{why}; pass --detect-landmarks or --face-box-default"))
            continue
        items.append(BatchItem(image, source, rel, landmarks))
    return items, skipped


@dataclass(frozen=True)
class PersonGroup:
    """The photographs of one person, fitted together into one result folder.

    Attributes
    ----------
    relative : PurePosixPath
        The person's output path (``Name``).
    items : tuple of BatchItem
        The photographs fitted, in input order (one: a single fit).
    """

    relative: PurePosixPath
    items: tuple[BatchItem, ...]


_NUMBERED = re.compile(r"^(.+?)_\d+$")


def person_of(relative: PurePosixPath) -> PurePosixPath:
    """Return the person an image shows: its folder, or its stem without ``_<number>`` at the top.

    >>> person_of(PurePosixPath("Aaron_Peirsol/Aaron_Peirsol_0002"))
    PurePosixPath('Aaron_Peirsol')
    >>> person_of(PurePosixPath("Aaron_Peirsol_0002"))
    PurePosixPath('Aaron_Peirsol')
    """
    rel = PurePosixPath(relative)
    if len(rel.parts) > 1:
        return rel.parent
    m = _NUMBERED.match(rel.name)
    return PurePosixPath(m.group(1) if m else rel.name)


def group_by_person(items: list[BatchItem], *, max_per_person: int
                    ) -> tuple[list[PersonGroup], list[Skipped]]:
    """Group images by :func:`person_of`; a person's photographs past ``max_per_person`` are skipped.

    Parameters
    ----------
    items : list of BatchItem
        In input order (the first ``max_per_person`` of each person are fitted).
    max_per_person : int
        At least 1.

    Returns
    -------
    (list of PersonGroup, list of Skipped)
        Groups in order of their first image; the photographs left out, with the reason.
    """
    if max_per_person < 1:
        raise ValueError(f"max_per_person must be >= 1, got {max_per_person}")
    groups: dict[PurePosixPath, list[BatchItem]] = {}
    for item in items:
        groups.setdefault(person_of(item.relative), []).append(item)
    out, skipped = [], []
    for person, members in groups.items():
        out.append(PersonGroup(person, tuple(members[:max_per_person])))
        for item in members[max_per_person:]:
            skipped.append(Skipped(item.source, str(item.relative),
                                   f"{person} has {len(members)} photographs; the first "
                                   f"{max_per_person} are fitted jointly (--max-per-person)"))
    return out, skipped
