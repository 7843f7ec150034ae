"""The chain session of a problem: a single fit's or a joint fit's.

This module imports :mod:`mcmcfit.fitting.chain_session`, :mod:`mcmcfit.fitting.joint_problem`
and :mod:`mcmcfit.fitting.joint_session`.
"""

from __future__ import annotations

import numpy as np

from mcmcfit.fitting.chain_session import ChainSession
from mcmcfit.fitting.joint_problem import JointProblem
from mcmcfit.fitting.joint_session import JointChainSession

__all__ = ["chain_session"]


def chain_session(problem, index: int, seed: np.random.SeedSequence, *,
                  threads: int | None = None) -> ChainSession | JointChainSession:
    """Return the session of chain ``index`` of ``problem`` (a FitProblem or a JointProblem)."""
    if isinstance(problem, JointProblem):
        return JointChainSession(problem, index, seed, threads=threads)
    return ChainSession(problem, index, seed, threads=threads)
