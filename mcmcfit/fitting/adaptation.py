"""Warm-up adaptation of the proposals' step sizes: one multiplier per family, by acceptance.

During warm-up the image stage runs in windows; after each window every
random-walk family (:data:`proposals.schedule.FAMILIES`: pose, shape, albedo,
expression, colour transform, light, specular exponent) has its step-size
multiplier moved towards an acceptance rate of about 0.25 (Roberts, Gelman &
Gilks 1997: 0.234 for high-dimensional random walks) and the schedule is
rebuilt with the new multipliers. The multipliers are frozen for the kept
draws, so the kept chain is a time-homogeneous Markov chain (adapting them
while keeping draws would break its stationarity unless the adaptation
diminished; freezing is the simple, exact choice, as Stan's warm-up does).

The gradient moves (:class:`proposals.gradient.MALA`) get their step size
tuned the same way towards 0.57 (Roberts & Rosenthal 1998, the optimal
acceptance of Langevin proposals), and their diagonal preconditioner set to
the variances of the warm-up draws (:func:`initial_diagonal` before any).

This module imports :mod:`albedo_model.params` and :mod:`proposals.gradient`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from albedo_model.params import Block, RenderParameter
from proposals.gradient import vector_layout

__all__ = ["MALA_BLOCKS", "MALA_TARGET", "MIN_PROPOSED", "TARGET_ACCEPTANCE", "adapt_step",
           "initial_diagonal", "adapt_scales", "family_counts"]

#: The blocks the gradient moves take: the nonlinear continuous geometry.
MALA_BLOCKS = Block.SHAPE | Block.EXPRESSION | Block.POSE | Block.CAMERA
#: Acceptance rate the Langevin step size is tuned to.
MALA_TARGET = 0.57
#: Acceptance rate the step sizes are tuned to.
TARGET_ACCEPTANCE = 0.25
#: Proposals of a family needed before its step size is adapted.
MIN_PROPOSED = 15
_MIN_SCALE, _MAX_SCALE = 1e-4, 4.0


def family_counts(proposal: np.ndarray, accepted: np.ndarray, names: tuple[str, ...],
                  family: Mapping[str, str]) -> dict[str, tuple[int, int]]:
    """Count ``(proposed, accepted)`` per family over some steps.

    Parameters
    ----------
    proposal : (n,) int, index into ``names`` of each step's proposal
    accepted : (n,) bool
    names : tuple of str, proposal names (a move's name may carry an ``@anchor`` suffix)
    family : mapping leaf name -> family (:func:`proposals.schedule.family_of`)

    Returns
    -------
    dict family -> (proposed, accepted)
    """
    prop = np.bincount(proposal, minlength=len(names))
    acc = np.bincount(proposal, weights=np.asarray(accepted, np.float64), minlength=len(names))
    out: dict[str, list[int]] = {}
    for i, name in enumerate(names):
        fam = family.get(name.split("@")[0])
        if fam is None or prop[i] == 0:
            continue
        c = out.setdefault(fam, [0, 0])
        c[0] += int(prop[i])
        c[1] += int(acc[i])
    return {k: (v[0], v[1]) for k, v in out.items()}


def adapt_scales(scales: Mapping[str, float], counts: Mapping[str, tuple[int, int]], *,
                 families: tuple[str, ...], target: float = TARGET_ACCEPTANCE,
                 targets: Mapping[str, float] | None = None) -> dict[str, float]:
    """Return new step-size multipliers from one window's acceptance.

    ``log k += 2 (a - target)``, with ``a`` the family's acceptance rate in the
    window and ``target`` the family's entry of ``targets`` if any; a family
    accepted below 5 % is divided by 3 outright (its steps are far too large:
    in a sharp posterior the reference's scales can be 100x too big).
    Families proposed fewer than 15 times keep their multiplier. Multipliers
    stay in [1e-4, 4].
    """
    out = {f: float(scales.get(f, 1.0)) for f in families}
    for fam in families:
        proposed, acc = counts.get(fam, (0, 0))
        if proposed < MIN_PROPOSED:
            continue
        rate = acc / proposed
        goal = (targets or {}).get(fam, target)
        k = out[fam]
        k = k / 3.0 if rate < 0.05 else k * math.exp(2.0 * (rate - goal))
        out[fam] = float(min(_MAX_SCALE, max(_MIN_SCALE, k)))
    return out


def adapt_step(step: float, counts: tuple[int, int], *, target: float = MALA_TARGET) -> float:
    """Return a gradient move's new step size from ``(proposed, accepted)`` (as :func:`adapt_scales`)."""
    proposed, acc = counts
    if proposed < MIN_PROPOSED:
        return float(step)
    rate = acc / proposed
    new = step / 3.0 if rate < 0.05 else step * math.exp(2.0 * (rate - target))
    return float(min(1.0, max(1e-4, new)))


#: Initial preconditioner entries (variances of the flat vector's entries before any
#: warm-up draw): coefficients in prior sds, angles (0.01 rad)^2, translations (1 mm)^2.
_INITIAL_VARIANCE = {"coefficient": 1.0, "angle": 1e-4, "translation": 1.0}


def initial_diagonal(params: RenderParameter) -> np.ndarray:
    """Return the gradient moves' preconditioner before warm-up, in :func:`vector_layout` order.

    Coefficients 1 (their prior sd), angles (0.01 rad)^2, translations (1 mm)^2,
    the focal length (1 % of it)^2.
    """
    out = []
    for block, n in vector_layout(params, MALA_BLOCKS):
        if block in (Block.SHAPE, Block.EXPRESSION):
            out.append(np.full(n, _INITIAL_VARIANCE["coefficient"]))
        elif block == Block.POSE:
            out.append(np.array([_INITIAL_VARIANCE["angle"]] * 3
                                + [_INITIAL_VARIANCE["translation"]] * 3))
        else:
            out.append(np.full(n, (0.01 * params.camera.focal_length) ** 2))
    return np.concatenate(out) if out else np.zeros(0)
