"""Everything a fit writes into its result folder.

:func:`write_fit_outputs` (:mod:`mcmcfit.outputs.folder`) writes, into a folder
the caller makes atomic (:func:`mcmcfit.jobs.fit_job.atomic_folder`): the posterior
albedo (``posterior.npz``), best and mean parameters (``.rps``), pictures of
the fit, the albedo and its uncertainty, the mean mesh, the chains, the summary
and the HTML report. The pieces live in small modules: posterior albedo
(:mod:`~mcmcfit.outputs.albedo_summary`, over the per-vertex summaries of
:mod:`~mcmcfit.outputs.posterior`), per-vertex values as pictures
(:mod:`~mcmcfit.outputs.vertex_maps`), matplotlib figures
(:mod:`~mcmcfit.outputs.figures`), ``summary.json``
(:mod:`~mcmcfit.outputs.summary`), ``report.html``
(:mod:`~mcmcfit.outputs.report`, styled by :mod:`~mcmcfit.outputs.html_style`)
errors against a known truth (:mod:`~mcmcfit.outputs.truth`, with the
scores of :mod:`~mcmcfit.outputs.accuracy`) and the ArviZ ``InferenceData``
``posterior.nc`` (:mod:`~mcmcfit.outputs.inference_data`).

The package imports :mod:`albedo_model` (camera, errors, model, params, pca,
io.image_io, io.mesh_export, io.rps, render.renderer), :mod:`mcmcfit.fitting.result`,
:mod:`mcmcfit.sampling` (chain, derived, diagnostics, param_vector) and
:mod:`mcmcfit.targets.landmarks`. This file
imports :mod:`mcmcfit.outputs.folder` on first use of its names.
"""

__all__ = ["OUTPUT_FILES", "write_fit_outputs"]


def __getattr__(name: str):
    # lazy: importing a small module of this package (e.g. html_style) must not load JAX
    if name in __all__:
        from mcmcfit.outputs import folder

        return getattr(folder, name)
    raise AttributeError(f"module 'mcmcfit.outputs' has no attribute {name!r}")
