"""Alternative landmark stage: emcee's affine-invariant ensemble over pose and camera.

Samples ``theta = (yaw, pitch, roll, t_x, t_y, log f, pp_x, pp_y)`` (rad, mm,
log sensor units, NDC) with the distance ``t_z`` and every other parameter
fixed at the start, targeting ``log p(x) + l_lm(x) + log f``: the last term is
the Jacobian of ``f -> log f``, so the ensemble samples the same posterior as
the MH landmark stage restricted to these coordinates, except that the angles
are confined to (-pi, pi) and log f to within 10 of its start (outside: -inf),
which keeps walkers from wandering to the back of the head. Moves: differential
evolution (0.8) and DE snooker (0.2), which mix well for these few
correlated coordinates. Walkers start in a small ball around the start.

This module imports :mod:`albedo_model.params`, :mod:`mcmcfit.sampling.chain` and
:mod:`mcmcfit.sampling.param_vector` (and emcee).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

from albedo_model.params import RenderParameter
from mcmcfit.sampling.chain import BestSample, ChainRecord
from mcmcfit.sampling.param_vector import ParamLayout

__all__ = ["EMCEE_COORDINATES", "params_of", "run_emcee_stage", "theta_of"]

#: The ensemble's coordinates, in order.
EMCEE_COORDINATES = ("yaw", "pitch", "roll", "tx", "ty", "log_f", "pp_x", "pp_y")
_SCATTER = np.array([0.03, 0.03, 0.01, 3.0, 3.0, 0.01, 0.005, 0.005])


def theta_of(params: RenderParameter) -> np.ndarray:
    """(8,) ensemble coordinates of ``params``."""
    p = params
    return np.array([p.pose.yaw, p.pose.pitch, p.pose.roll, p.pose.translation[0],
                     p.pose.translation[1], math.log(p.camera.focal_length),
                     *p.camera.principal_point])


def params_of(theta: np.ndarray, template: RenderParameter) -> RenderParameter:
    """Parameters with the ensemble coordinates ``theta`` set, the rest from ``template``."""
    t = [float(v) for v in theta]
    pose = template.pose._replace(yaw=t[0], pitch=t[1], roll=t[2],
                                  translation=(t[3], t[4], template.pose.translation[2]))
    cam = template.camera._replace(focal_length=math.exp(t[5]), principal_point=(t[6], t[7]))
    return template._replace(pose=pose, camera=cam)


def run_emcee_stage(rng: np.random.Generator, start: RenderParameter,
                    log_prior: Callable[[RenderParameter], float],
                    log_lik_lm: Callable[[RenderParameter], float], layout: ParamLayout, *,
                    n_steps: int, n_walkers: int = 32, thin: int = 1,
                    progress: Callable[[int, int], None] | None = None) -> ChainRecord:
    """Run the ensemble landmark stage.

    Parameters
    ----------
    rng : numpy Generator (seeds emcee's RandomState and the initial ball)
    start : RenderParameter
    log_prior, log_lik_lm : callables of RenderParameter
    layout : ParamLayout
    n_steps : int
        Ensemble iterations (each evaluates every walker once).
    n_walkers : int (>= 2 x 8 + 2 recommended)
    thin : int
        Keep every ``thin``-th iteration of every walker.
    progress : callable ``(done, total)``, optional

    Returns
    -------
    ChainRecord
        ``sampler="emcee"``, ``steps=0``; ``samples`` are the kept walker
        positions (iteration-major), ``log_prior``/``log_lik_lm`` their values;
        ``extra`` holds ``acceptance_fraction`` and ``n_walkers``.
    """
    import emcee  # imported here: it pulls in scipy.stats (~2 s)

    t0 = time.perf_counter()
    ndim = len(EMCEE_COORDINATES)

    theta0 = theta_of(start)

    def log_prob(theta: np.ndarray):
        if not (np.all(np.abs(theta[:3]) < math.pi) and abs(theta[5] - theta0[5]) < 10.0
                and np.all(np.isfinite(theta))):
            return -math.inf, -math.inf, -math.inf
        p = params_of(theta, start)
        lp = float(log_prior(p))
        if not math.isfinite(lp):
            return -math.inf, lp, -math.inf
        lm = float(log_lik_lm(p))
        return lp + lm + float(theta[5]), lp, lm

    p0 = theta0 + rng.normal(size=(n_walkers, ndim)) * _SCATTER
    sampler = emcee.EnsembleSampler(
        n_walkers, ndim, log_prob, blobs_dtype=[("log_prior", float), ("log_lik_lm", float)],
        moves=[(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)])
    sampler.random_state = np.random.RandomState(int(rng.integers(2**32))).get_state()
    n_steps = max(int(n_steps), 1)
    for i, _ in enumerate(sampler.sample(p0, iterations=n_steps), start=1):
        if progress is not None and (i % 10 == 0 or i == n_steps):
            progress(i, n_steps)
    thin = max(1, int(thin))
    chain = sampler.get_chain()  # (n_steps, walkers, ndim)
    blobs = sampler.get_blobs()
    lp_all, lm_all = blobs["log_prior"], blobs["log_lik_lm"]
    kept = chain[thin - 1::thin].reshape(-1, ndim)
    lp = lp_all[thin - 1::thin].reshape(-1)
    lm = lm_all[thin - 1::thin].reshape(-1)
    vectors = np.array([layout.to_vector(params_of(t, start)) for t in kept]).reshape(-1, layout.size)

    def best(score: np.ndarray) -> BestSample:
        j = np.unravel_index(int(np.argmax(score)), score.shape)
        p = params_of(chain[j], start)
        return BestSample(p, int(j[0]), float(lp_all[j]), float(lm_all[j]), 0.0)

    best_lm, best_post = best(lm_all), best(lp_all + lm_all)
    steps_idx = np.repeat(np.arange(thin - 1, n_steps, thin), n_walkers)
    return ChainRecord(
        "landmarks", "emcee", thin, 0, layout, steps_idx.astype(np.int64), vectors,
        lp.astype(float), lm.astype(float), np.zeros_like(lp, float), np.zeros(0, np.int32), (),
        np.zeros(0, bool), np.zeros(0, np.int8), best_post, best_lm, best_post,
        time.perf_counter() - t0,
        {"acceptance_fraction": float(np.mean(sampler.acceptance_fraction)),
         "n_walkers": int(n_walkers), "iterations": n_steps})
