"""``mcmcfit bench render``: wall time of one sampler step per proposal kind.

A sampler step is: the proposal's parameters -> :meth:`Renderer.update` (only the
stages the changed block makes stale) -> shading fused with a Gaussian pixel
log-likelihood (:meth:`Renderer.compose`) -> the scalar on the host -> accept or
reject (at fixed rates close to a real fit's, :data:`ACCEPT_EVERY`). The same steps are
timed on the naive path (:class:`mcmcfit.bench.naive_step.NaiveStep`, nothing
cached), and with the specular term switched off (an effect that is off must be
cheaper, not multiplied by zero).

Each path is one chain that mixes the proposal kinds as a sampler does
(:data:`CYCLE`: shape 40 %, pose, albedo and light 20 % each, interleaved), so
that every step finds the caches a real fit leaves for it; steps are timed per
kind. The chains of one image size take turns of one cycle each, so that other
processes on the machine slow them alike and the ratios stay meaningful; the
medians are still wall times under whatever load there was (the table prints
the load average).

Model: :func:`mcmcfit.bench.synthetic_face.synthetic_face_model` (53,824
vertices, 106,722 triangles; shape 50 + expression 5, albedo 50 shared), seen
frontally so that the face covers about 60 % of the pixels.

The result records and the table are in :mod:`mcmcfit.bench.render_report`.

This module imports :mod:`albedo_model` (camera, params, render.raycast,
render.renderer) and :mod:`mcmcfit.bench` (naive_step, render_report, synthetic_face).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from threadpoolctl import threadpool_limits

from albedo_model.params import (
    Block, MoMoCoefficients, Pose, RenderParameter, SHLight, default_square, fit_to_image_size,
)
from albedo_model.camera import camera_rays
from albedo_model.render.raycast import RayCaster, default_threads, embree_pass
from albedo_model.render.renderer import Renderer
from mcmcfit.bench.naive_step import NaiveStep
from mcmcfit.bench.render_report import MIX, BenchResult, BenchRow, format_table
from mcmcfit.bench.synthetic_face import synthetic_face_model

__all__ = ["KINDS", "MIX", "BenchRow", "BenchResult", "face_scene", "run_render_bench",
           "format_table"]

#: Proposal kinds and the blocks they touch.
KINDS = {"pose": Block.POSE, "shape": Block.SHAPE, "albedo": Block.ALBEDO, "light": Block.LIGHT}
_BLOCK = 10  # coefficients per shape / albedo proposal
_SIGMA = 0.05  # pixel noise of the likelihood (linear RGB)


def face_scene(model, size: int, coverage: float = 0.6) -> RenderParameter:
    """Frontal scene of ``size``² pixels in which the face covers about ``coverage``.

    The distance is solved from the projected area of the face's outline
    (an ellipse of the model's x/y extent) with the default camera.
    """
    p = fit_to_image_size(default_square(), size, size)
    v = model.vertices
    half_w, half_h = (v[:, 0].max() - v[:, 0].min()) / 2, (v[:, 1].max() - v[:, 1].min()) / 2
    f_px = size * p.camera.focal_length / p.camera.sensor_size[0]
    # pi a b (f / d)^2 = coverage * size^2 for the outline (the rim lies near z = 0)
    dist = f_px * np.sqrt(np.pi * half_w * half_h / (coverage * size * size))
    n_shape, n_albedo = model.shape.rank, model.diffuse.rank
    n_expr = 0 if model.expression is None else model.expression.rank
    sh = SHLight.frontal().coefficients.copy()
    sh[1:4] += (0.05, 0.1, -0.05)
    return p._replace(
        pose=Pose(1.0, (0.0, 0.0, -float(dist)), 0.0, 0.05, 0.0),
        environment_map=SHLight(sh),
        momo=MoMoCoefficients(np.zeros(n_shape), np.zeros(n_albedo), np.zeros(n_expr)),
    )


def _proposal(params: RenderParameter, kind: str, step: int, rng: np.random.Generator):
    m = params.momo
    if kind == "pose":
        return params._replace(pose=params.pose._replace(yaw=params.pose.yaw + rng.normal(0, 0.01)))
    if kind in ("shape", "albedo"):
        coeffs = m.shape if kind == "shape" else m.albedo
        start = (_BLOCK * step) % max(len(coeffs), 1)
        new = coeffs.copy()
        new[start:start + _BLOCK] += rng.normal(0, 0.1, len(new[start:start + _BLOCK]))
        momo = m._replace(shape=new) if kind == "shape" else m._replace(albedo=new)
        return params._replace(momo=momo)
    sh = params.environment_map.coefficients + rng.normal(0, 0.01, (9, 3))
    return params._replace(environment_map=SHLight(sh))


def _log_lik(rgb, mask, target, inv_two_var):
    """Gaussian pixel log-likelihood (up to a constant) over the face pixels."""
    sq = sum((rgb[c] - target[c]) ** 2 for c in range(3))
    return -inv_two_var * jnp.sum(jnp.where(mask, sq, 0.0))


def _log_lik_on_set(rgb, mask, pixels, target, inv_two_var):
    """:func:`_log_lik` on a renderer's pixel set (as a fit evaluates it)."""
    if pixels is not None:
        target = tuple(t[pixels] for t in target)
    return _log_lik(rgb, mask, target, inv_two_var)


def _target(renderer: Renderer, params: RenderParameter, rng: np.random.Generator):
    """Make a fixed target: the scene with other albedo and light, plus noise (device arrays)."""
    m = params.momo
    other = params._replace(
        momo=m._replace(albedo=rng.normal(0, 0.5, len(m.albedo))),
        environment_map=SHLight(params.environment_map.coefficients * 1.1),
    )
    img = renderer.render(other).image.reshape(-1, 3)
    img = img + rng.normal(0, _SIGMA, img.shape).astype(np.float32)
    return tuple(jax.device_put(np.ascontiguousarray(img[:, c])) for c in range(3))


#: Every n-th proposal of a kind is accepted: rounded from the demo fit's rates
#: (``summary.json``: shape 24 %, pose 3-26 %, albedo 46 %, SH light 21 %).
ACCEPT_EVERY = {"shape": 4, "pose": 4, "albedo": 2, "light": 4}

#: One turn of a sampler's proposal mix (as in performance-notes.md §4: 40/20/20/20).
CYCLE = ("shape", "albedo", "pose", "shape", "light", "shape", "albedo", "pose", "shape", "light")


_TURN = 20  # steps of one chain before the next chain's turn


class _Chain:
    """One renderer stepping through a cycle of proposal kinds, timed per kind.

    Parameters
    ----------
    params : RenderParameter
        Start.
    rng : numpy.random.Generator
        Proposal noise.
    cycle : tuple of str
        Proposal kinds in the order they are made, repeated.
    renderer, naive
        The path: a :class:`Renderer` (cached stages) or a :class:`NaiveStep`.

    Notes
    -----
    Every ``ACCEPT_EVERY[kind]``-th proposal of a kind is accepted, the others
    rejected.
    """

    def __init__(self, params: RenderParameter, rng: np.random.Generator, cycle: tuple,
                 renderer: Renderer | None = None, naive: NaiveStep | None = None):
        self.rng, self.cycle, self.renderer, self.naive = rng, cycle, renderer, naive
        self.i = 0
        self.counts = dict.fromkeys(KINDS, 0)
        self.times: dict[str, list[float]] = {kind: [] for kind in KINDS}
        if renderer is not None:
            self.log_lik = renderer.compose(_log_lik_on_set, pixel_set=True)
            self.state = renderer.init_state(params)
        self.params = params

    def step(self, target, inv) -> None:
        """Make the next proposal of the cycle, evaluate it, and accept or reject it."""
        kind = self.cycle[self.i % len(self.cycle)]
        n = self.counts[kind]
        proposed = _proposal(self.params, kind, n, self.rng)
        accept = n % ACCEPT_EVERY[kind] == 0
        t0 = time.perf_counter()
        if self.naive is not None:
            value = self.naive(proposed, target, inv)
        else:
            cand = self.renderer.update(self.state, proposed, KINDS[kind])
            value = float(self.log_lik(cand, target, inv))
            if accept:
                self.state = self.renderer.accept(cand)
            else:
                self.renderer.reject()
        self.times[kind].append(time.perf_counter() - t0)
        if not np.isfinite(value):
            raise FloatingPointError(f"{kind}: log-likelihood is {value}")
        if accept:
            self.params = proposed
        self.counts[kind] += 1
        self.i += 1

    def ms(self, kind: str, skip: int, stat=np.median) -> float:
        """``stat`` (median or mean) of the step times of ``kind`` after ``skip``, in ms."""
        return 1e3 * float(stat(self.times[kind][skip:]))


def _spread(total: int, parts: int) -> list[int]:
    """``total`` split into ``parts`` near-equal non-negative integers."""
    return [int(x) for x in np.diff(np.linspace(0, total, parts + 1).round())]


def _time_size(model, size: int, steps: int, warmup: int, naive_steps: int, threads: int,
               seed: int, log) -> tuple[list[BenchRow], str]:
    """All chains of one image size, in turns so that load hits them alike."""
    params = face_scene(model, size)
    rng = np.random.default_rng([seed, size])

    def renderer(specular: bool) -> Renderer:
        return Renderer(model, specular=specular, threads=threads)

    # pose, albedo and light chains share a renderer (they leave the vertices alone);
    # shape chains and the mixed chain move the scene and get their own
    shared = {True: renderer(True), False: renderer(False)}
    target = _target(shared[True], params, rng)
    coverage = float(shared[True].render(params).mask.mean())
    naive = NaiveStep(model, shared[True].effects(params), jax.jit(_log_lik), threads=threads)
    chains = {}
    for k, kind in enumerate(KINDS):
        for spec in (True, False):
            r = renderer(spec) if kind == "shape" else shared[spec]
            chains[kind, spec] = _Chain(params, np.random.default_rng([seed, size, k]), (kind,),
                                        renderer=r)
        chains[kind, "naive"] = _Chain(params, np.random.default_rng([seed, size, k]), (kind,),
                                       naive=naive)
    mixed = _Chain(params, np.random.default_rng([seed, size, len(KINDS)]), CYCLE,
                   renderer=renderer(True))
    inv = jnp.float32(0.5 / _SIGMA**2)
    turns = -(-(steps + warmup) // _TURN)
    per_cycle = min(CYCLE.count(k) for k in KINDS)
    mixed_warm = -(-warmup // per_cycle)
    mixed_cycles = _spread(-(-steps // per_cycle) + mixed_warm, turns)
    naive_turns = _spread(naive_steps + 1, turns)  # + 1: the first naive step compiles
    log(f"{size}x{size}: {len(chains)} one-kind chains in {turns} turns of {_TURN} steps, "
        f"and a mixed chain of {sum(mixed_cycles)} cycles")
    for t in range(turns):
        for key, chain in chains.items():
            for _ in range(naive_turns[t] if key[1] == "naive" else _TURN):
                chain.step(target, inv)
        for _ in range(mixed_cycles[t] * len(CYCLE)):
            mixed.step(target, inv)
    mixed_skip = {k: mixed_warm * CYCLE.count(k) for k in KINDS}
    rows = [BenchRow(size, kind, chains[kind, True].ms(kind, warmup),
                     chains[kind, False].ms(kind, warmup),
                     chains[kind, "naive"].ms(kind, 1), coverage,
                     mixed.ms(kind, mixed_skip[kind]), mixed.ms(kind, mixed_skip[kind], np.mean),
                     chains[kind, "naive"].ms(kind, 1, np.mean))
            for kind in KINDS]
    return rows, "refit" if mixed.renderer.refit_supported else "rebuild"


def _embree_reference(model, size: int = 250, repeats: int = 15) -> tuple[float, float]:
    """Time a single-threaded ray cast of the mean face at ``size``², with and without bookkeeping.

    Median ms of one :meth:`RayCaster.cast` and of the bare Embree query inside
    it (:func:`albedo_model.render.raycast.embree_pass`), timed alternately.

    A yardstick of the machine: ``performance-notes.md`` measured 6.6 ms for the
    bare Embree call on its 53k-vertex face (1 thread, non-robust traversal, 62 %
    coverage); ``cast`` adds the back-face test and its output arrays (a few per cent).
    """
    params = face_scene(model, size)
    origins, directions = camera_rays(params.camera, params.image_size, params.pose, params.view)
    tfar = params.camera.far - params.camera.near
    caster = RayCaster(model.vertices, model.triangles, threads=1, update="rebuild")
    times: dict[str, list[float]] = {"cast": [], "bare": []}
    for _ in range(repeats + 1):
        for key, run in (("cast", lambda: caster.cast(origins, directions, tfar=tfar,
                                                       image_shape=(size, size))),
                         ("bare", lambda: embree_pass(caster, origins, directions, tfar))):
            t0 = time.perf_counter()
            run()
            times[key].append(time.perf_counter() - t0)
    return tuple(1e3 * float(np.median(times[k][1:])) for k in ("cast", "bare"))


def run_render_bench(sizes: Sequence[int] = (128, 250, 512), steps: int = 40, *,
                     threads: int | None = None, warmup: int = 3, naive_steps: int | None = None,
                     seed: int = 0, grid: int = 232, model=None,
                     log: Callable[[str], None] | None = None) -> BenchResult:
    """Time sampler steps per proposal kind and image size (see the module notes).

    Parameters
    ----------
    sizes : sequence of int
        Square image sizes in pixels.
    steps : int
        Timed steps of each kind and size, at least (median reported; whole
        cycles of :data:`CYCLE` are run, so shape steps are twice as many),
        after at least ``warmup`` steps of each kind.
    threads : int, optional
        Ray-casting threads (both paths); default :func:`default_threads`.
    naive_steps : int, optional
        Timed naive steps of each kind, at least (default ``min(steps, 10)``:
        the naive path is slow).
    seed : int
        Seed of the synthetic model, the target and the proposals.
    grid : int
        Grid resolution of the synthetic model (232: 53,824 vertices, 106,722
        triangles; smaller for quick checks).
    model : MorphableModel, optional
        Instead of the synthetic model (its build time is reported).
    log : callable, optional
        Progress messages.

    Returns
    -------
    BenchResult
    """
    log = log or (lambda _msg: None)
    threads = default_threads() if threads is None else int(threads)
    naive_steps = min(steps, 10) if naive_steps is None else naive_steps
    load_before = os.getloadavg()
    t0 = time.perf_counter()
    model = synthetic_face_model(seed, grid, grid) if model is None else model
    build_s = time.perf_counter() - t0
    log(f"model: {model.n_vertices} vertices, {model.n_triangles} triangles, "
        f"built in {build_s:.2f} s")
    embree_ms, embree_bare_ms = _embree_reference(model)
    rows, method = [], "?"
    with threadpool_limits(limits=1, user_api="blas"):  # as in a fit (mcmcfit.fitting.fit)
        for size in sizes:
            size_rows, method = _time_size(model, int(size), steps, warmup, naive_steps,
                                           threads, seed, log)
            rows += size_rows
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return BenchResult(rows, int(cores or 1), threads, method, steps, build_s, model.n_vertices,
                       model.n_triangles, embree_ms, embree_bare_ms, load_before,
                       os.getloadavg())
