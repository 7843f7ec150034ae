"""The chains of one fit, run in this process or in parallel worker processes.

Both pools expose one call, ``pool.call(method, *args)``: every chain's
:func:`~mcmcfit.fitting.sessions.chain_session` runs ``method(*args)``
and the results come back in chain order. The driver calls them in lockstep
(landmarks, warm-up, noise, rounds of draws), so a fit gives the same chains
whichever pool runs them; only wall time differs.

:class:`ProcessPool` starts one worker process per chain (a fresh
interpreter: JAX and Embree are not fork-safe once initialised), each with one
ray-casting thread, one BLAS thread and single-threaded XLA, and sends each
the :class:`~mcmcfit.fitting.problem.FitProblem` once (model and image
included). A worker that fails sends its exception back; the pool raises
:class:`WorkerError` in the parent and stops every worker.

This module imports :mod:`mcmcfit.fitting.sessions` and
:mod:`mcmcfit.fitting.problem` (the workers run :mod:`mcmcfit.fitting.chain_worker`).
"""

from __future__ import annotations

import os
import secrets
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from contextlib import contextmanager
from multiprocessing.connection import Listener

import numpy as np

from mcmcfit.fitting.sessions import chain_session
from mcmcfit.fitting.problem import FitProblem

__all__ = ["LocalPool", "ProcessPool", "WorkerError", "chain_pool"]


class WorkerError(RuntimeError):
    """A chain's worker process failed; the message holds its traceback."""


class LocalPool:
    """All chains in this process, one after the other."""

    def __init__(self, problem: FitProblem, seeds: Sequence[np.random.SeedSequence], *,
                 threads: int | None = None):
        self.sessions = [chain_session(problem, i, s, threads=threads)
                         for i, s in enumerate(seeds)]

    def call(self, method: str, *args, **kwargs) -> list:
        """Run ``session.method(*args, **kwargs)`` for every chain; results in chain order."""
        return [getattr(s, method)(*args, **kwargs) for s in self.sessions]

    def call_each(self, method: str, args_per_chain: Sequence[tuple]) -> list:
        """Run ``session.method(*args_i)`` with per-chain arguments."""
        return [getattr(s, method)(*a) for s, a in zip(self.sessions, args_per_chain)]

    def close(self) -> None:
        """Nothing to stop."""


@contextmanager
def _single_threaded_children():
    """Environment of the worker processes: one thread each for BLAS and XLA."""
    saved = {k: os.environ.get(k) for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS",
                                            "MKL_NUM_THREADS", "XLA_FLAGS")}
    os.environ.update(OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    flags = (saved["XLA_FLAGS"] or "").split()
    flags += ["--xla_cpu_multi_thread_eigen=false", "intra_op_parallelism_threads=1"]
    os.environ["XLA_FLAGS"] = " ".join(dict.fromkeys(flags))
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


class ProcessPool:
    """One worker process per chain, driven in lockstep over authenticated local sockets.

    Each worker is a fresh interpreter running :mod:`mcmcfit.fitting.chain_worker`
    (``python -m``), not a ``multiprocessing`` child: a spawned child would
    re-import the caller's main script, which breaks every script without an
    ``if __name__ == "__main__"`` guard.
    """

    def __init__(self, problem: FitProblem, seeds: Sequence[np.random.SeedSequence]):
        authkey = secrets.token_bytes(16)
        folder = tempfile.mkdtemp(prefix="mcmcfit-chains-")
        address = os.path.join(folder, "socket")
        self._conns, self._procs = [], []
        listener = Listener(address, family="AF_UNIX", authkey=authkey)
        try:
            with _single_threaded_children():
                env = dict(os.environ, MCMCFIT_WORKER_KEY=authkey.hex())
                for _ in seeds:
                    self._procs.append(subprocess.Popen(
                        [sys.executable, "-m", "mcmcfit.fitting.chain_worker", address], env=env))
            for i, s in enumerate(seeds):
                conn = listener.accept()
                conn.send((problem, i, s))
                self._conns.append(conn)
        except BaseException:
            self.close()
            raise
        finally:
            listener.close()
            shutil.rmtree(folder, ignore_errors=True)
        self._collect()

    def _collect(self) -> list:
        out, errors = [], []
        for i, conn in enumerate(self._conns):
            try:
                status, value = conn.recv()
            except (EOFError, OSError):
                status, value = "error", "worker process died"
            if status == "error":
                errors.append(f"chain {i}: {value}")
            out.append(value)
        if errors:
            self.close()
            raise WorkerError("\n".join(errors))
        return out

    def call(self, method: str, *args, **kwargs) -> list:
        """Run ``session.method(*args, **kwargs)`` in every worker; results in chain order."""
        for conn in self._conns:
            conn.send((method, args, kwargs))
        return self._collect()

    def call_each(self, method: str, args_per_chain: Sequence[tuple]) -> list:
        """Run ``session.method(*args_i)`` with per-chain arguments."""
        for conn, a in zip(self._conns, args_per_chain):
            conn.send((method, tuple(a), {}))
        return self._collect()

    def close(self) -> None:
        """Stop every worker (idempotent)."""
        for conn in self._conns:
            try:
                conn.send(None)
                conn.close()
            except (BrokenPipeError, OSError):
                pass
        for proc in self._procs:
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        self._conns, self._procs = [], []


def chain_pool(problem: FitProblem, seeds: Sequence[np.random.SeedSequence], *,
               processes: bool):
    """Return a :class:`ProcessPool` (``processes`` and more than one chain) or a :class:`LocalPool`."""
    if processes and len(seeds) > 1:
        return ProcessPool(problem, seeds)
    return LocalPool(problem, seeds)
