"""Batch fitting: many images, one task per image, atomic per-image outputs, resumable.

Modules
-------
discovery
    Input images (a folder walked recursively, or a text file listing them)
    and the landmark file of each.
out_paths
    Output folders derived safely from input paths; complete / stale folders.
seeds
    Per-image seeds derived from the root seed and the relative path.
face_boxes
    The default face box of LFW's 250x250 crops.
task
    :class:`~mcmcfit.batch.task.FitTask` and :func:`~mcmcfit.batch.task.run_task`, the
    function a worker runs.
records
    The ``batch.jsonl`` fields of a finished image (acceptance, landmark RMS,
    albedo digest).
worker_env
    Per-process thread limits, set before NumPy/JAX start their thread pools.
journal
    ``batch.jsonl`` / ``failures.jsonl``: one fsynced JSON line per event.
pool_runner, dask_runner
    Run tasks on a local process pool or a Dask distributed cluster.
run
    :func:`~mcmcfit.batch.run.run_batch`: plan, run, journal, progress bar.
report_data, report_plots, report
    ``mcmcfit batch-report``: rows per image, plots, the HTML page and the CSV.

Layout of OUT::

    OUT/<relative path without extension>/   one complete `mcmcfit fit` result folder
    OUT/batch.jsonl                          one line per finished image
    OUT/failures.jsonl                       one line per failed or skipped image

The heavy modules (fitting, JAX) are imported only inside the worker's task,
so that importing this package is cheap and a spawned worker can limit its
threads before JAX starts. (:mod:`mcmcfit.batch.run`, used by the parent
process only, imports :mod:`mcmcfit.fitting.config` and with it JAX.)

This file imports nothing; its modules import :mod:`albedo_model` (``errors``,
``io.atomic``), :mod:`mcmcfit.fitting.config` and :mod:`mcmcfit.jobs.fit_job`.
"""
