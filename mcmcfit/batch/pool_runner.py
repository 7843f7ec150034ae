"""Run batch tasks on a local process pool (spawned workers, one image per task).

Workers are started with the ``spawn`` method, so they begin without the
parent's NumPy / JAX thread pools, and their initialiser
(:func:`mcmcfit.batch.worker_env.init_pool_worker`) sets the thread limits
before the first task imports JAX, makes the worker die with the batch
process, and optionally pins it to a core. A worker that dies (killed,
out of memory, a crash in native code) breaks the pool: the pool is started
again and the images that were in flight are retried, up to ``retries``
times each, before they are reported as failed.

This module imports :mod:`mcmcfit.batch` modules and the standard library.
"""

from __future__ import annotations

import multiprocessing
import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool

from mcmcfit.batch.task import FitTask, run_task
from mcmcfit.batch.worker_env import init_pool_worker, thread_env

__all__ = ["pool_outcomes", "lost_outcome"]


def lost_outcome(task: FitTask, reason: str) -> dict:
    """Return the outcome of a task whose worker never returned."""
    return {"path": task.source, "relative": task.relative, "seed": task.seed,
            "status": "failed", "seconds": None, "reason": reason,
            "error_type": "WorkerLost"}


def _bounded_pass(tasks: list[FitTask], workers: int, make_pool, fn,
                  suspects: list[FitTask]) -> Iterator[dict]:
    """Run ``tasks`` with at most ``workers`` in flight, restarting the pool after a break.

    Tasks in flight when the pool breaks are appended to ``suspects``.
    """
    todo = list(reversed(tasks))
    while todo:
        pool = make_pool(workers)
        finished = False
        try:
            in_flight: dict = {}
            broken = False
            while (todo or in_flight) and not broken:
                while todo and len(in_flight) < workers and not broken:
                    task = todo.pop()
                    try:
                        in_flight[pool.submit(fn, task)] = task
                    except BrokenProcessPool:
                        todo.append(task)
                        broken = True
                if not in_flight:
                    break
                done, _ = wait(in_flight, return_when=FIRST_COMPLETED)
                if broken or any(isinstance(f.exception(), BrokenProcessPool) for f in done):
                    broken = True
                    done, _ = wait(in_flight)  # a broken pool resolves every future at once
                for fut in done:
                    task = in_flight.pop(fut)
                    exc = fut.exception()
                    if isinstance(exc, BrokenProcessPool):
                        suspects.append(task)
                    elif exc is not None:  # pickling or another pool-level error
                        yield lost_outcome(task, f"{type(exc).__name__}: {exc}")
                    else:
                        yield fut.result()
            finished = True
        finally:
            # a normal end waits for the workers to exit; an interrupted one (Ctrl-C, the
            # consumer stopped) drops what is queued and leaves without waiting
            pool.shutdown(wait=finished, cancel_futures=not finished)
        if todo:
            time.sleep(0.2)  # let the dead pool's processes go before starting a new one


def pool_outcomes(tasks: Iterable[FitTask], *, workers: int, threads: int = 1,
                  pin: bool = False, retries: int = 2,
                  fn: Callable[[FitTask], dict] = run_task) -> Iterator[dict]:
    """Outcomes of ``tasks`` (:func:`mcmcfit.batch.task.run_task` dicts) as they finish.

    Parameters
    ----------
    tasks : iterable of FitTask
    workers : int >= 1
        Worker processes.
    threads : int >= 1
        Thread limit per worker (:func:`mcmcfit.batch.worker_env.thread_env`).
    pin : bool
        Pin each worker to one core (round robin over the allowed cores).
    retries : int
        How often an image that was in flight when a worker died is run again
        alone (see the module docstring); 0 reports it as failed at once.
    fn : callable ``(FitTask) -> dict``
        The task function, a module-level function (it is pickled by name).

    Yields
    ------
    dict
        One outcome per task, in completion order.
    """
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    ctx = multiprocessing.get_context("spawn")
    counter = ctx.Value("i", 0) if pin else None

    def make_pool(n: int) -> ProcessPoolExecutor:
        return ProcessPoolExecutor(max_workers=n, mp_context=ctx, initializer=init_pool_worker,
                                   initargs=(thread_env(threads), counter))

    suspects: list[FitTask] = []
    yield from _bounded_pass(list(tasks), workers, make_pool, fn, suspects)
    for task in suspects:
        for _ in range(retries):
            lost: list[FitTask] = []
            outcomes = list(_bounded_pass([task], 1, make_pool, fn, lost))
            if not lost:
                yield from outcomes
                break
        else:
            yield lost_outcome(task, f"the worker process died ({1 + retries} attempts, "
                               f"{retries} of them alone)")
