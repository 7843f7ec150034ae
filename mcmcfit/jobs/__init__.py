"""Fits as files: an image (+ landmarks) on disk in, a complete result folder out.

Modules
-------
model_spec
    A model named on the command line: a path or ``default``.
fit_job
    :func:`~mcmcfit.jobs.fit_job.run_fit_job`: read, fit, write atomically.
synthetic_case
    A face of a model with known truth, rendered over a textured background (the demo).
texture_job
    :func:`~mcmcfit.jobs.texture_job.write_fit_textures`: a result folder's maps as
    textures and a textured mesh (``mcmcfit texture``).

This file imports nothing; its modules import :mod:`albedo_model`, :mod:`mcmcfit.fitting`,
:mod:`mcmcfit.outputs` and :mod:`pipeline.synthetic` (the ``default`` model, LFW landmark
names).
"""
