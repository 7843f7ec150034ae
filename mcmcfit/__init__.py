"""mcmcfit: posterior face albedo from one photograph, by MCMC analysis-by-synthesis.

Subpackages: likelihoods, sampler, posterior, diagnostics, fitting, command line.
``mcmcfit`` may import ``albedo_model``, ``proposals`` and ``pipeline``; nothing
imports ``mcmcfit``.
"""

import os
from importlib.metadata import PackageNotFoundError, version

# One BLAS thread: OpenBLAS workers spin and steal the second core from Embree
# and XLA (performance-notes.md §6). Only a default; the environment wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

try:
    __version__ = version("mcmcfit")
except PackageNotFoundError:  # running from a source tree without install
    __version__ = "0.0.0+unknown"

__all__ = ["__version__"]
