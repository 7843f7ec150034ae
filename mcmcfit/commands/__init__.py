"""The ``mcmcfit`` subcommands, one module each (loaded by :mod:`mcmcfit.cli`).

Modules
-------
model, model_sample, model_specgen
    ``mcmcfit model``: ``info``, ``combine``, ``sample`` and ``specgen``.
params
    ``mcmcfit params convert``: any ``.rps`` version -> V4.
render
    ``mcmcfit render``: render the instance an ``.rps`` describes.
fit
    ``mcmcfit fit``: one photograph -> one result folder; the shared schedule options.
demo
    ``mcmcfit demo``: fit a synthetic face with known truth and report the albedo error.
pipeline, pipeline_build, pipeline_simulate
    ``mcmcfit pipeline``: ``stitch``, ``simulate`` and ``build``.
batch
    ``mcmcfit batch`` and ``mcmcfit batch-report``.
bench
    ``mcmcfit bench``: the ``render`` and ``fit`` benchmarks.
evaluate
    ``mcmcfit evaluate``: the paper's held-out experiment (Table 1).
subcommands
    ``add_action``: what the ``register_<action>`` functions of a command group share.

Each command module exposes ``register(subparsers)`` (``subcommands`` is a helper, not a
command). This file imports nothing; the command modules import :mod:`albedo_model`,
:mod:`mcmcfit` and :mod:`pipeline` modules, most of them only when a command runs.
"""