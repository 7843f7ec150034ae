"""Run batch tasks on a Dask distributed cluster (one task per image).

With a scheduler address (``tcp://host:8786``) the tasks go to an existing
cluster; otherwise a :class:`distributed.LocalCluster` of ``workers``
single-threaded worker processes on the loopback interface is started for the
batch and closed after it. Each task is :func:`mcmcfit.batch.task.run_task`:
the worker reads the image and writes the result folder itself, so INPUT,
the landmarks, the model file and OUT must be on storage every worker sees
under the same paths (a shared file system); only the small outcome dict
travels back, and the client process writes the journals.

Worker loss: the scheduler re-runs a task whose worker died, up to
``distributed.scheduler.allowed-failures`` times (Dask's default 3); after
that the image is recorded as failed (``KilledWorker``). ``retries`` re-runs a
task that raised, which :func:`run_task` itself never does for a bad image.

Thread limits: a LocalCluster's workers get the variables of
:func:`mcmcfit.batch.worker_env.thread_env` in their environment; on a
cluster started by someone else, :func:`run_task` sets them before the first
fit when the user has not (start workers with ``--nthreads 1`` and, ideally,
``OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1``).

This module imports :mod:`mcmcfit.batch` modules; :mod:`distributed` and
:mod:`albedo_model.errors` are imported when a batch runs.
"""

from __future__ import annotations

import uuid
from collections.abc import Callable, Iterable, Iterator

from mcmcfit.batch.pool_runner import lost_outcome
from mcmcfit.batch.task import FitTask, run_task
from mcmcfit.batch.worker_env import thread_env

__all__ = ["dask_outcomes", "task_key"]


def task_key(task: FitTask) -> str:
    """Return a readable, unique Dask key for one image's task."""
    return f"mcmcfit-fit-{task.relative}-{uuid.uuid4().hex[:8]}"


def _client(scheduler: str | None, workers: int, threads: int):
    try:
        from distributed import Client, LocalCluster
    except ImportError:  # pragma: no cover - distributed is a dependency
        from albedo_model.errors import InputError

        raise InputError("Dask is not installed: pip install 'dask[distributed]'") from None
    if scheduler:
        try:
            return Client(scheduler, timeout="20s"), None
        except (OSError, TimeoutError, ValueError) as exc:
            from albedo_model.errors import InputError

            raise InputError(f"cannot reach the Dask scheduler at {scheduler} "
                             f"({type(exc).__name__}: {exc})") from None
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                           host="127.0.0.1", dashboard_address=None, env=thread_env(threads),
                           silence_logs=40)
    return Client(cluster), cluster


def dask_outcomes(tasks: Iterable[FitTask], *, scheduler: str | None = None, workers: int = 1,
                  threads: int = 1, retries: int = 1,
                  fn: Callable[[FitTask], dict] = run_task) -> Iterator[dict]:
    """Outcomes of ``tasks`` run on a Dask cluster, as they finish.

    Parameters
    ----------
    tasks : iterable of FitTask
    scheduler : str, optional
        Address of a running scheduler; None starts a LocalCluster.
    workers : int
        Worker processes of the LocalCluster (ignored with ``scheduler``).
    threads : int
        Thread limit per worker process.
    retries : int
        Dask retries of a task that raised.
    fn : callable ``(FitTask) -> dict``
        The task function (module-level, importable on the workers).

    Yields
    ------
    dict
        One :func:`run_task` outcome per task; a task lost for good gives a
        "failed" outcome with the Dask error.
    """
    from distributed import as_completed

    tasks = list(tasks)
    if not tasks:
        return
    client, cluster = _client(scheduler, workers, threads)
    try:
        futures = {}
        for t in tasks:
            fut = client.submit(fn, t, key=task_key(t), pure=False, retries=retries)
            futures[fut.key] = (fut, t)
        for fut in as_completed([f for f, _ in futures.values()]):
            task = futures[fut.key][1]
            try:
                yield fut.result()
            except Exception as exc:  # KilledWorker, cancelled, communication errors
                yield lost_outcome(task, f"{type(exc).__name__}: {exc}")
            fut.release()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
