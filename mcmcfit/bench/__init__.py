"""Benchmarks of the hot paths: ``mcmcfit bench render`` (:mod:`mcmcfit.bench.render_bench`).

``python -m mcmcfit.bench render`` runs the same benchmark.

Modules
-------
render_bench, render_report
    One sampler step per proposal kind, cached against naive; its records and table.
naive_step
    The naive sampler step the renderer's caching is measured against.
synthetic_face
    A synthetic, BFM-sized morphable model for the render benchmark.
fit_bench
    ``mcmcfit bench fit``: the default schedule on the demo case.
__main__
    ``python -m mcmcfit.bench render|fit``.

The package imports :mod:`albedo_model` (camera, model, params, pca, io.atomic,
render, shading), :mod:`mcmcfit.fitting`, :mod:`mcmcfit.jobs.synthetic_case` and
:mod:`mcmcfit.outputs.accuracy`; its ``__main__`` also imports :mod:`mcmcfit` and
:mod:`mcmcfit.commands.bench`. This file imports nothing.
"""

__all__: list[str] = []
