"""Per-image seeds derived from the root seed and the image's relative path.

The seed of an image depends only on the root seed and the image's relative
output path, never on the order of the images, the number of workers or the
engine (process pool or Dask), so every way of running a batch gives the same
numbers, and adding images to a batch does not change the others.

This module imports only the standard library.
"""

from __future__ import annotations

import hashlib
from pathlib import PurePosixPath

__all__ = ["image_seed"]

_DOMAIN = b"mcmcfit-batch-seed-v1"


def image_seed(root_seed: int, relative: PurePosixPath | str) -> int:
    """Return the seed of one image: 63 bits of SHA-256 over the root seed and the path.

    Parameters
    ----------
    root_seed : int
        The batch's ``--seed`` (>= 0).
    relative : PurePosixPath or str
        The image's relative output path (``Name/Name_0001``), POSIX separators.

    Returns
    -------
    int in [0, 2**63)
    """
    if int(root_seed) < 0:
        raise ValueError(f"root seed must be >= 0, got {root_seed}")
    digest = hashlib.sha256(b"\0".join([_DOMAIN, str(int(root_seed)).encode(),
                                        str(PurePosixPath(relative)).encode("utf-8")])).digest()
    return int.from_bytes(digest[:8], "big") >> 1
