"""mcmcfit: posterior face albedo from one photograph, by MCMC analysis-by-synthesis.

The public Python API (imported on first use, so that ``import mcmcfit`` stays
cheap and a batch worker can limit its threads before JAX starts):

=====================  ===============================================================
``fit``                fit a model to an image array: :func:`mcmcfit.fitting.fit.fit`
``fit_joint``          fit several photographs of one face: :func:`mcmcfit.fitting.joint_fit.fit_joint`
``FitConfig``          the settings of a fit: :class:`mcmcfit.fitting.config.FitConfig`
``FitResult``          what a fit returns: :class:`mcmcfit.fitting.result.FitResult`
``run_fit_job``        an image file in, a result folder out (what ``mcmcfit fit`` does):
                       :func:`mcmcfit.jobs.fit_job.run_fit_job`
``run_joint_fit_job``  several image files in, one result folder out:
                       :func:`mcmcfit.jobs.joint_job.run_joint_fit_job`
``write_fit_textures`` a result folder's maps as textures (``mcmcfit texture``):
                       :func:`mcmcfit.jobs.texture_job.write_fit_textures`
``write_fit_outputs``  write a result folder: :func:`mcmcfit.outputs.folder.write_fit_outputs`
``load_model``         a model file or ``"default"``: :func:`mcmcfit.jobs.model_spec.load_model_spec`
``read_image``         an image file as floats in [0, 1]: :func:`albedo_model.io.image_io.read_image`
``read_landmarks``     a ``.tlms`` file: :func:`albedo_model.io.tlms.read_tlms`
``synthetic_case``     a face with known truth: :func:`mcmcfit.jobs.synthetic_case.synthetic_case`
=====================  ===============================================================

Subpackages, in the order of the data flow: ``sampling`` (the MH kernel, chain
records, diagnostics), ``targets`` (likelihoods, priors), ``proposal_data``,
``fitting`` (one fit), ``outputs`` (posterior summaries, pictures, report),
``jobs`` (fits as files), ``batch``, ``bench``, ``commands`` (the CLI); see
``docs/architecture.md``. ``mcmcfit`` may import ``albedo_model``, ``proposals``
and ``pipeline``; nothing imports ``mcmcfit``.

This module imports no project module when loaded: each name above imports its
module (:func:`importlib.import_module`) on first use.
"""

import importlib
import os
from importlib.metadata import PackageNotFoundError, version

# One BLAS thread: OpenBLAS workers spin and steal the second core from Embree
# and XLA (performance-notes.md §6). Only a default; the environment wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

try:
    __version__ = version("mcmcfit")
except PackageNotFoundError:  # running from a source tree without install
    __version__ = "0.0.0+unknown"

_API = {
    "fit": ("mcmcfit.fitting.fit", "fit"),
    "fit_joint": ("mcmcfit.fitting.joint_fit", "fit_joint"),
    "FitConfig": ("mcmcfit.fitting.config", "FitConfig"),
    "FitResult": ("mcmcfit.fitting.result", "FitResult"),
    "run_fit_job": ("mcmcfit.jobs.fit_job", "run_fit_job"),
    "run_joint_fit_job": ("mcmcfit.jobs.joint_job", "run_joint_fit_job"),
    "write_fit_textures": ("mcmcfit.jobs.texture_job", "write_fit_textures"),
    "write_fit_outputs": ("mcmcfit.outputs.folder", "write_fit_outputs"),
    "load_model": ("mcmcfit.jobs.model_spec", "load_model_spec"),
    "read_image": ("albedo_model.io.image_io", "read_image"),
    "read_landmarks": ("albedo_model.io.tlms", "read_tlms"),
    "synthetic_case": ("mcmcfit.jobs.synthetic_case", "synthetic_case"),
}

__all__ = ["__version__", *_API]


def __getattr__(name: str):
    if name in _API:
        module, attr = _API[name]
        return getattr(importlib.import_module(module), attr)
    raise AttributeError(f"module 'mcmcfit' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_API))
