"""Stand-in task functions for testing the batch runners' plumbing without fits.

They are module-level so that spawned pool workers and Dask workers import them
by name. None of them fits anything: they report what the worker process looks
like, die, or raise.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path


def describe_worker(task) -> dict:
    """An "ok" outcome describing the worker: pid, thread variables, JAX loaded, affinity."""
    env = {k: os.environ.get(k) for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                                          "MKL_NUM_THREADS", "XLA_FLAGS")}
    affinity = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None
    return {"path": task.source, "relative": task.relative, "seed": task.seed, "status": "ok",
            "seconds": 0.0, "pid": os.getpid(), "env": env, "affinity": affinity,
            "jax_loaded": "jax" in sys.modules}


def write_folder(task) -> dict:
    """Write a result folder with summary.json (like a fit job) unless the image is named 'bad'."""
    if "bad" in task.source:
        return {"path": task.source, "relative": task.relative, "seed": task.seed,
                "status": "failed", "seconds": 0.0, "reason": "bad input",
                "error_type": "InputError"}
    out = Path(task.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.json").write_text(json.dumps({"seed": task.seed}))
    return {**describe_worker(task), "acceptance": 0.25}


def die_once(task) -> dict:
    """Kill the worker process the first time a task runs (marker file beside out_dir)."""
    marker = Path(task.out_dir + ".died")
    if not marker.exists():
        marker.parent.mkdir(parents=True, exist_ok=True)
        marker.write_text("x")
        os._exit(3)
    return describe_worker(task)


def die_always(task) -> dict:
    """Kill the worker process every time."""
    os._exit(4)


def raise_error(task) -> dict:
    """Raise (the real task never does; the runners must still report it)."""
    raise RuntimeError(f"unexpected failure for {task.source}")


def die_for_i1(task) -> dict:
    """Kill the worker for the image named ``i1`` (every time); describe the worker otherwise."""
    if task.relative.endswith("/i1"):
        os._exit(5)
    return describe_worker(task)
