"""``mcmcfit evaluate``: the paper's held-out experiment (Table 1), out of model.

Modules
-------
cases
    The models built without the held-out subjects (intrinsic, baked textures)
    and the photographs of the held-out subjects in each scene, with their truth.
scores
    Scores of an albedo estimate against the truth (arrays in, numbers out).
score_fit
    One result folder scored against its case's truth.
table
    Mean +- sd per model and scene: ``table.md`` (Table 1 form), ``table.csv``.
plots
    ``calibration.png`` and ``accuracy_time.png``.
report
    ``report.html``: the table, the plots and a row of pictures per case.
run
    :func:`~mcmcfit.evaluation.run.run_evaluation`: cases, one batch per model,
    scores, outputs.

Layer: above :mod:`mcmcfit.batch` and :mod:`mcmcfit.bench`, below
:mod:`mcmcfit.commands`. This file imports nothing; its modules import
:mod:`albedo_model`, :mod:`pipeline.synthetic` (the population, models and
scenes), :mod:`mcmcfit.batch`, :mod:`mcmcfit.outputs` and :mod:`mcmcfit.fitting.config`.
"""
