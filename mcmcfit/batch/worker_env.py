"""Per-process thread limits for batch workers.

Two workers on two cores must not each start a thread per core in OpenMP,
OpenBLAS, MKL and XLA: they would fight for the cores (performance-notes.md
§5: a spinning OpenBLAS pool took the second core from Embree and XLA). The
limits are environment variables, which those libraries read once, when they
start, so they are set in the worker before anything imports NumPy or JAX:
in the process pool's initialiser (spawned workers start clean), in the Dask
workers' environment (``LocalCluster(env=...)``), and, for workers started by
someone else, at the start of the first task when JAX is not loaded yet.

XLA's flags alone do not bound its CPU use (performance-notes.md §3), so a
worker can also be pinned to cores (``os.sched_setaffinity``), which bounds
every library at once, Embree's TBB pool included.

This module imports only the standard library.
"""

from __future__ import annotations

import os
import sys

__all__ = ["THREAD_VARIABLES", "thread_env", "apply_thread_env", "pin_to_cores",
           "init_pool_worker", "usable_cores", "die_with_parent"]

#: Thread-count variables of the numeric libraries a fit loads.
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                    "NUMEXPR_NUM_THREADS", "VECLIB_MAXIMUM_THREADS")

_XLA_SINGLE = "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"


def usable_cores() -> int:
    """Cores this process may run on (its affinity mask when the OS has one)."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return max(1, os.cpu_count() or 1)


def thread_env(threads: int) -> dict[str, str]:
    """Environment variables that limit one worker to ``threads`` threads per library.

    Parameters
    ----------
    threads : int >= 1

    Returns
    -------
    dict
        The :data:`THREAD_VARIABLES` and, for one thread, ``XLA_FLAGS``
        (merged with the current value).
    """
    if threads < 1:
        raise ValueError(f"threads must be >= 1, got {threads}")
    env = {k: str(int(threads)) for k in THREAD_VARIABLES}
    if threads == 1:
        current = os.environ.get("XLA_FLAGS", "")
        if "xla_cpu_multi_thread_eigen" not in current:
            env["XLA_FLAGS"] = (current + " " + _XLA_SINGLE).strip()
    return env


def apply_thread_env(env: dict[str, str], *, override: bool = True) -> bool:
    """Put ``env`` into ``os.environ``; return False when JAX was already imported.

    With ``override=False`` variables the user has set are kept.
    """
    for key, value in env.items():
        if override or key not in os.environ:
            os.environ[key] = value
    return "jax" not in sys.modules


def pin_to_cores(slot: int) -> list[int]:
    """Pin this process to one allowed core chosen by ``slot`` (round robin); return it.

    Does nothing (returns ``[]``) where the OS has no CPU affinity.
    """
    if not hasattr(os, "sched_setaffinity"):
        return []
    cores = sorted(os.sched_getaffinity(0))
    core = cores[slot % len(cores)]
    os.sched_setaffinity(0, {core})
    return [core]


def init_pool_worker(env: dict[str, str], counter=None) -> None:
    """Initialise a spawned pool worker: die with the parent, thread limits, core pinning.

    Parameters
    ----------
    env : dict
        From :func:`thread_env`.
    counter : multiprocessing.Value('i'), optional
        Shared counter giving each worker its pinning slot; None: no pinning.
    """
    die_with_parent()
    apply_thread_env(env)
    if counter is not None:
        with counter.get_lock():
            slot = counter.value
            counter.value += 1
        pin_to_cores(slot)


def die_with_parent() -> bool:
    """Ask Linux to SIGKILL this process when its parent dies (``PR_SET_PDEATHSIG``).

    A batch killed with SIGKILL cannot stop its pool workers; without this they
    would finish their current image and rename it into OUT while a re-run is
    already fitting the same image. Returns False where unsupported.
    """
    if not sys.platform.startswith("linux"):
        return False
    import ctypes
    import signal

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        pr_set_pdeathsig = 1
        if libc.prctl(pr_set_pdeathsig, int(signal.SIGKILL), 0, 0, 0) != 0:
            return False
    except (OSError, AttributeError):
        return False
    if os.getppid() == 1:  # the parent died before prctl took effect
        os._exit(1)
    return True
