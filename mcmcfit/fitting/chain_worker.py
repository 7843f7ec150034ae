"""A chain's worker process: ``python -m mcmcfit.fitting.chain_worker ADDRESS``.

Started by :class:`mcmcfit.fitting.chain_pool.ProcessPool`. It connects to the
parent's socket (authenticated with the key in ``MCMCFIT_WORKER_KEY``),
receives ``(problem, index, seed)``, builds its session
(:func:`mcmcfit.fitting.sessions.chain_session`: a single or a joint fit's) and then runs
``(method, args, kwargs)`` requests until it receives None, answering each with
``("ok", result)`` or ``("error", traceback text)``.

This module imports :mod:`mcmcfit.fitting.sessions`.
"""

from __future__ import annotations

import os
import sys
import traceback
from multiprocessing.connection import Client

__all__ = ["main"]


def main(address: str) -> int:
    """Serve one chain for the parent at ``address``; return the exit code."""
    from threadpoolctl import threadpool_limits

    conn = Client(address, family="AF_UNIX",
                  authkey=bytes.fromhex(os.environ.get("MCMCFIT_WORKER_KEY", "")))
    try:
        with threadpool_limits(limits=1, user_api="blas"):
            from mcmcfit.fitting.sessions import chain_session

            problem, index, seed = conn.recv()
            session = chain_session(problem, index, seed, threads=1)
            conn.send(("ok", None))
            while True:
                msg = conn.recv()
                if msg is None:
                    return 0
                method, args, kwargs = msg
                conn.send(("ok", getattr(session, method)(*args, **kwargs)))
    except EOFError:
        return 0
    except BaseException as exc:  # noqa: BLE001 -- every failure goes back to the parent
        try:
            conn.send(("error", f"{type(exc).__name__}: {exc}\n{traceback.format_exc()}"))
        except OSError:
            pass
        return 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
