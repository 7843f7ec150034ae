"""A landmark stage from several starts: short chains from each, the best one continued.

One landmark chain started at the pose guess can stay in the guess's mode
when the landmark posterior has others: the mirrored yaw (landmarks alone fix
the yaw's sign only through perspective), and a ridge along the distance on
which a nearer or farther head with a zoomed camera and another yaw explains
the landmarks almost as well. (Starts cannot fix a wrong mode that is the
posterior's highest, e.g. one made by a landmark the mean shape hides at the
true pose.) :func:`landmark_stage` runs a short MH chain from each of a few starts
built from the guess (:func:`build_starts`), keeps the one whose short run reached
the highest log posterior (taken in log distance and log focal length, see
:func:`landmark_stage`) and continues it for the rest of the budget, so the stage
costs the same number of steps as one chain.

The starts: the guess; its yaw mirrored (or, for a near-frontal guess, a yaw of
+-25 deg, since mirroring ~0 changes nothing); the distance times 0.6 and 1.6
with the focal length scaled alike. The landmark likelihood cannot tell the
distance from the focal length except through perspective, so a distance start
with an unscaled focal length would only start from a face of the wrong image
size, which the first zoom moves undo; scaled, it starts on the far or near end
of the ridge, from where the chain reaches the mode of that end by the small
moves it makes best. Each start is re-centred so that its projected landmarks
keep the guess's image centroid (a yaw about the head's origin moves the face
sideways in the image).

This module imports :mod:`albedo_model` (camera, params), :mod:`mcmcfit.sampling`
(chain, kernel, param_vector) and :mod:`mcmcfit.fitting.cache_check` (for the type).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np

from albedo_model.camera import pixel_scale, project
from albedo_model.params import RenderParameter
from mcmcfit.fitting.cache_check import CacheCheck
from mcmcfit.sampling.chain import ChainRecord, ChainRecorder
from mcmcfit.sampling.kernel import ChainState, init, step
from mcmcfit.sampling.param_vector import ParamLayout

__all__ = ["DEFAULT_STARTS", "EXPLORE_FRACTION", "Start", "build_starts", "landmark_stage"]

#: The kinds of start :func:`build_starts` makes by default.
DEFAULT_STARTS = ("guess", "mirrored", "near", "far")
#: Share of the stage's steps spent on the short chains (split evenly over the starts).
EXPLORE_FRACTION = 0.2
#: A guess with |yaw| below this (deg) is near frontal: "mirrored" gives two side starts.
NEAR_FRONTAL_DEG = 10.0
#: The yaw (deg) of the side starts of a near-frontal guess.
SIDE_YAW_DEG = 25.0
#: Distance factors of the "near" and "far" starts (focal length scaled alike).
DISTANCE_FACTORS = {"near": 0.6, "far": 1.6}

_PROGRESS_EVERY = 25


class Start(NamedTuple):
    """One start of the landmark stage: its name (``guess``, ``yaw+25``, ...) and parameters."""

    name: str
    params: RenderParameter


def _distance(p: RenderParameter) -> float:
    return float(p.view.translation[2] - p.pose.translation[2])


def _centroid(target, p: RenderParameter) -> np.ndarray | None:
    """Image centroid (2,) of the landmark factor's projected model landmarks (None: unusable)."""
    factor = getattr(target, "landmarks", None)
    geometry, names = getattr(factor, "geometry", None), getattr(factor, "names", None)
    if geometry is None or not names:
        return None
    px, depth = project(geometry.points(list(names), p), p.pose, p.view, p.camera, p.image_size)
    if not (np.all(np.isfinite(px)) and np.all(depth > 0)):
        return None
    return px.mean(axis=0)


def _recentred(target, p: RenderParameter, goal: np.ndarray | None) -> RenderParameter:
    """``p`` translated in x, y so that its landmark centroid is at ``goal`` (two Newton steps)."""
    if goal is None:
        return p
    for _ in range(2):
        c = _centroid(target, p)
        if c is None:
            return p
        fx, fy = pixel_scale(p.camera, p.image_size)
        d = _distance(p)
        tx, ty, tz = p.pose.translation
        # u grows with x, v (down) falls with y: pixels per mm at the head are f_px / d
        tx += (goal[0] - c[0]) * d / fx
        ty -= (goal[1] - c[1]) * d / fy
        p = p._replace(pose=p.pose._replace(translation=(float(tx), float(ty), float(tz))))
    return p


def _at_distance(p: RenderParameter, factor: float) -> RenderParameter:
    """``p`` with the distance and the focal length times ``factor`` (same image size)."""
    tx, ty, _ = p.pose.translation
    tz = float(p.view.translation[2]) - factor * _distance(p)
    pose = p.pose._replace(translation=(factor * float(tx), factor * float(ty), tz))
    return p._replace(pose=pose, camera=p.camera._replace(
        focal_length=float(p.camera.focal_length) * factor))


def build_starts(params0: RenderParameter, target=None, *,
                 kinds: Sequence[str] = DEFAULT_STARTS) -> list[Start]:
    """Return the starts of the landmark stage built from the pose guess ``params0``.

    Parameters
    ----------
    params0 : RenderParameter
        The pose guess (:func:`~mcmcfit.fitting.initialisation.pose_from_landmarks`).
    target : FaceTarget, optional
        With a landmark or face-box factor, every start is re-centred so that its
        projected model landmarks keep the guess's image centroid.
    kinds : sequence of {"guess", "mirrored", "near", "far"}
        ``mirrored`` is yaw -> -yaw, or, when the guess is within
        :data:`NEAR_FRONTAL_DEG` of frontal, the two starts ``yaw+25`` and
        ``yaw-25`` (:data:`SIDE_YAW_DEG`); ``near`` / ``far`` scale the distance
        and the focal length by :data:`DISTANCE_FACTORS`.

    Returns
    -------
    list of Start
        In the order of ``kinds``.

    Raises
    ------
    ValueError
        An unknown kind, or one given twice.
    """
    unknown = [k for k in kinds if k not in DEFAULT_STARTS]
    if unknown or len(set(kinds)) != len(kinds):
        raise ValueError(f"start kinds must be distinct ones of {DEFAULT_STARTS}, got {kinds!r}")
    goal = _centroid(target, params0) if target is not None else None
    yaw = float(params0.pose.yaw)
    out: list[Start] = []
    for kind in kinds:
        if kind == "guess":
            out.append(Start(kind, params0))
        elif kind == "mirrored" and abs(math.degrees(yaw)) >= NEAR_FRONTAL_DEG:
            p = params0._replace(pose=params0.pose._replace(yaw=-yaw))
            out.append(Start(kind, _recentred(target, p, goal)))
        elif kind == "mirrored":
            for sign in (1.0, -1.0):
                p = params0._replace(pose=params0.pose._replace(
                    yaw=sign * math.radians(SIDE_YAW_DEG)))
                out.append(Start(f"yaw{sign * SIDE_YAW_DEG:+g}", _recentred(target, p, goal)))
        else:
            p = _at_distance(params0, DISTANCE_FACTORS[kind])
            out.append(Start(kind, _recentred(target, p, goal)))
    return out


def _describe(start: Start) -> dict:
    p = start.params
    return {"name": start.name, "yaw_deg": math.degrees(p.pose.yaw),
            "pitch_deg": math.degrees(p.pose.pitch), "roll_deg": math.degrees(p.pose.roll),
            "distance_mm": _distance(p), "focal_length": float(p.camera.focal_length)}


def _log_scale_score(state: ChainState) -> float:
    """Log posterior in log distance and log focal length: ``log p + log d + log f`` (Notes)."""
    p = state.params
    d, f = _distance(p), float(p.camera.focal_length)
    if not (d > 0.0 and f > 0.0):
        return -math.inf
    return float(state.log_posterior + math.log(d) + math.log(f))


def _steps(rng: np.random.Generator, state: ChainState, target, proposal, recorder: ChainRecorder,
           first: int, n: int, check: CacheCheck | None,
           tick: Callable[[], None]) -> tuple[ChainState, float]:
    """``n`` steps recorded as steps ``first, ...`` of ``recorder``; the final state, best score."""
    best = _log_scale_score(state)
    for i in range(first, first + n):
        state, info = step(rng, state, target, proposal, image=False)
        recorder(i, state, info)
        if check is not None:
            check(i, state, info)
        if info.accepted:
            best = max(best, _log_scale_score(state))
        tick()
    return state, best


def landmark_stage(rng: np.random.Generator, params0: RenderParameter, target, proposal,
                   n_steps: int, *, layout: ParamLayout, thin: int,
                   starts: Sequence[str] = DEFAULT_STARTS,
                   explore_fraction: float = EXPLORE_FRACTION,
                   progress: Callable[[int, int], None] | None = None,
                   check: CacheCheck | None = None) -> tuple[ChainRecord, dict]:
    """Run the landmark stage from several starts and continue the best (module notes).

    Each start runs ``n_short = explore_fraction n_steps / S`` steps; the start whose
    short run reached the highest log posterior, measured in log distance and log
    focal length (see Notes), runs on for the rest of the budget.

    Parameters
    ----------
    rng : numpy Generator
        The chain's generator; each start draws from its own child generator
        (spawned from ``rng`` in start order), the continuation from the chosen
        start's, so the result is deterministic given ``rng``. With one start the
        chain draws from ``rng`` itself: the same chain as one
        :func:`mcmcfit.sampling.kernel.run` of ``n_steps`` from ``params0``.
    params0 : RenderParameter
        The pose guess.
    target : FaceTarget
        The landmark-only target (no image likelihood).
    proposal : Proposal
        The landmark-stage proposal (:func:`proposals.schedule.landmark_stage_proposal`).
    n_steps : int
        Total MH steps of the stage, over all starts.
    layout : ParamLayout
        Columns of the kept samples.
    thin : int
        Keep every ``thin``-th sample.
    starts : sequence of str
        Kinds of start (:func:`build_starts`); ``("guess",)`` is the single-start stage.
    explore_fraction : float in (0, 1)
        Share of ``n_steps`` run as short chains, split evenly over the starts.
    progress : callable ``(done, total)``, optional
        Called every few steps with the steps done over all starts.
    check : CacheCheck, optional
        ``--check-cache``: called after each step of every chain.

    Returns
    -------
    record : ChainRecord
        The chosen start's chain, its short run and its continuation as one
        chain (``n_steps - (S - 1) * n_short`` steps for S starts); ``seconds``
        is the stage's whole wall time, ``extra["starts"]`` the description below.
    info : dict
        ``starts``: one dict per start (``name``, start ``yaw_deg``, ``pitch_deg``,
        ``roll_deg``, ``distance_mm``, ``focal_length``, ``steps`` run, the
        ``score`` and the ``best_log_posterior`` of its short run, ``chosen``);
        ``chosen``: the chosen start's name; ``short_steps``: steps of each short run.

    Notes
    -----
    The starts are compared by ``max (log p + log d + log f)`` over each short run
    (``d`` the distance, ``f`` the focal length): the log posterior of the chain's
    coordinates ``(t_z, f)`` carries the log-normal priors' ``-log d - log f``, which
    along the ridge of constant image size (``f / d`` fixed) rises by ~0.8 nats from
    1.2 m to 0.7 m whatever the data, and by 2 nats per e-fold below the priors'
    medians. On a likelihood flat along the ridge (a face box) the "near" start then
    won in 6 of 6 synthetic cases. In ``(log d, log f)`` the priors are Gaussians
    with their peak at the medians, and only the data's perspective decides.
    """
    t0 = time.perf_counter()
    n_steps = int(n_steps)
    built = build_starts(params0, target, kinds=starts)
    n_short = int(explore_fraction * n_steps) // len(built) if len(built) > 1 else 0
    if n_short == 0:
        built = built[:1]
    done = [0]

    def tick() -> None:
        done[0] += 1
        if progress is not None and (done[0] % _PROGRESS_EVERY == 0 or done[0] == n_steps):
            progress(done[0], n_steps)

    n_chosen = n_steps - (len(built) - 1) * n_short
    runs = []
    # one start is today's single chain, drawing from ``rng`` itself
    children = rng.spawn(len(built)) if len(built) > 1 else [rng]
    for start, child in zip(built, children):
        state = init(start.params, target, image=False)
        recorder = ChainRecorder(layout, n_short or n_chosen, thin, state, stage="landmarks")
        if check is not None:
            check(-1, state)
        state, score = _steps(child, state, target, proposal, recorder, 0, n_short, check, tick)
        runs.append((score, recorder.best_posterior.log_posterior, state, recorder, child))
    scores = np.array([r[0] for r in runs])
    best = int(np.argmax(np.where(np.isnan(scores), -np.inf, scores)))
    _, _, state, recorder, child = runs[best]
    recorder.extend(n_chosen - recorder.n)  # (the other starts' time is no step's time)
    _steps(child, state, target, proposal, recorder, n_short, n_chosen - n_short, check, tick)
    described = [dict(_describe(s), steps=n_short if i != best else n_chosen,
                      score=float(runs[i][0]), best_log_posterior=float(runs[i][1]),
                      chosen=i == best)
                 for i, s in enumerate(built)]
    info = {"starts": described, "chosen": built[best].name, "short_steps": n_short}
    record = recorder.record(time.perf_counter() - t0)
    record.extra["starts"] = described
    return record, info
