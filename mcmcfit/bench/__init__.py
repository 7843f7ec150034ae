"""Benchmarks of the hot paths: ``mcmcfit bench render`` (:mod:`mcmcfit.bench.render_bench`).

``python -m mcmcfit.bench render`` runs the same benchmark.
"""

__all__: list[str] = []
