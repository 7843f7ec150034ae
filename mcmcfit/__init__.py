"""mcmcfit: posterior face albedo from one photograph, by MCMC analysis-by-synthesis.

Subpackages: likelihoods, sampler, posterior, diagnostics, fitting, command line.
``mcmcfit`` may import ``albedo_model``, ``proposals`` and ``pipeline``; nothing
imports ``mcmcfit``.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("mcmcfit")
except PackageNotFoundError:  # running from a source tree without install
    __version__ = "0.0.0+unknown"

__all__ = ["__version__"]
