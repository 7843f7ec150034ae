"""Everything a fit writes into its result folder.

:func:`write_fit_outputs` (:mod:`mcmcfit.outputs.folder`) writes, into a folder
the caller makes atomic (:func:`mcmcfit.jobs.fit_job.atomic_folder`): the posterior
albedo (``posterior.npz``), best and mean parameters (``.rps``), pictures of
the fit, the albedo and its uncertainty, the mean mesh, the chains, the summary
and the HTML report. The pieces live in small modules: posterior albedo
(:mod:`~mcmcfit.outputs.albedo_summary`), per-vertex values as pictures
(:mod:`~mcmcfit.outputs.vertex_maps`), matplotlib figures
(:mod:`~mcmcfit.outputs.figures`), ``summary.json``
(:mod:`~mcmcfit.outputs.summary`) and errors against a known truth
(:mod:`~mcmcfit.outputs.truth`).
"""

__all__ = ["OUTPUT_FILES", "write_fit_outputs"]


def __getattr__(name: str):
    # lazy: importing a small module of this package (e.g. html_style) must not load JAX
    if name in __all__:
        from mcmcfit.outputs import folder

        return getattr(folder, name)
    raise AttributeError(f"module 'mcmcfit.outputs' has no attribute {name!r}")
