"""Journal files of a batch: one JSON object per line, appended and fsynced.

``OUT/batch.jsonl`` gets one line per finished image and ``OUT/failures.jsonl``
one line per failed or skipped image. Only the batch's parent process writes
them, one ``os.write`` of one whole line at a time on a descriptor opened with
``O_APPEND``, followed by ``fsync``. A process killed mid-write can still leave
a truncated last line (the kernel does not promise that a write is all or
nothing on power loss), so :func:`read_journal` ignores a last line that is not
complete JSON, and :func:`append_line` first ends such a line so that the new
record starts on a line of its own.

This module imports only the standard library.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

__all__ = ["BATCH_JOURNAL", "FAILURES_JOURNAL", "append_line", "read_journal", "to_jsonable"]

BATCH_JOURNAL = "batch.jsonl"
FAILURES_JOURNAL = "failures.jsonl"


def to_jsonable(value):
    """``value`` with NaN / inf floats as None, tuples as lists and NumPy scalars as Python."""
    if isinstance(value, dict):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_jsonable(v) for v in value]
    if hasattr(value, "item") and callable(value.item) and getattr(value, "ndim", 1) == 0:
        value = value.item()
    if hasattr(value, "tolist"):
        return to_jsonable(value.tolist())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def append_line(path: str | os.PathLike, record: dict) -> None:
    """Append ``record`` as one JSON line to ``path`` and fsync it.

    Parameters
    ----------
    path : path-like
        The journal (created when missing; its folder must exist).
    record : dict
        JSON-able after :func:`to_jsonable` (non-finite floats become null).
    """
    line = (json.dumps(to_jsonable(record), sort_keys=True, allow_nan=False) + "\n").encode()
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        size = os.fstat(fd).st_size
        if size:
            with open(path, "rb") as fh:
                fh.seek(size - 1)
                if fh.read(1) != b"\n":  # a truncated line from a killed writer
                    line = b"\n" + line
        view = memoryview(line)
        while view:
            n = os.write(fd, view)
            view = view[n:]
        os.fsync(fd)
    finally:
        os.close(fd)


def read_journal(path: str | os.PathLike) -> list[dict]:
    """Read the records of a journal, in file order; a missing file gives ``[]``.

    Lines that are not a complete JSON object (a truncated write) are skipped.
    """
    p = Path(path)
    if not p.is_file():
        return []
    out = []
    for line in p.read_bytes().split(b"\n"):
        if not line.strip():
            continue
        try:
            record = json.loads(line)
        except (json.JSONDecodeError, UnicodeDecodeError):
            continue
        if isinstance(record, dict):
            out.append(record)
    return out
