"""Result records and the text table of ``mcmcfit bench render``.

:class:`BenchRow` (ms per step of one proposal kind at one image size) and
:class:`BenchResult` (all rows plus the machine facts) are what
:func:`mcmcfit.bench.render_bench.run_render_bench` measures;
:func:`format_table` turns them into the printed table, with the steps/s of the
sampler's proposal mix (:data:`MIX`) and a comparison with the figures of
performance-notes.md §4 scaled to this machine (:data:`NOTES_STEP_MS`).

This module imports nothing from the project (only ``jax``, for its version).
"""

from __future__ import annotations

import dataclasses

import jax

__all__ = ["MIX", "NOTES_EMBREE_MS", "NOTES_STEP_MS", "BenchResult", "BenchRow", "format_table"]


@dataclasses.dataclass(frozen=True)
class BenchRow:
    """ms per step of one proposal kind at one image size.

    ``ours_ms``, ``ours_no_specular_ms`` and ``naive_ms`` are medians of chains
    making only this kind of proposal (steady state, as performance-notes.md §4
    measured); ``mixed_ms`` / ``mixed_mean_ms`` the median / mean of this kind's
    steps in a chain mixing all kinds as a sampler does (colder caches, and the
    first step after an accepted geometry builds the per-pixel caches).
    """

    size: int
    kind: str
    ours_ms: float
    ours_no_specular_ms: float
    naive_ms: float
    coverage: float
    mixed_ms: float
    mixed_mean_ms: float
    naive_mean_ms: float

    @property
    def speedup(self) -> float:
        """Naive / ours: how many times faster the cached path is."""
        return self.naive_ms / self.ours_ms


@dataclasses.dataclass(frozen=True)
class BenchResult:
    """All rows plus the machine facts the table prints."""

    rows: list[BenchRow]
    cores: int
    threads: int
    update_method: str
    steps: int
    build_s: float
    n_vertices: int
    n_triangles: int
    embree_ms: float
    embree_bare_ms: float
    load_before: tuple[float, float, float]
    load_after: tuple[float, float, float]


#: Proposal mix of the steps/s summary (as in performance-notes.md §4).
MIX = {"shape": 0.4, "pose": 0.2, "albedo": 0.2, "light": 0.2}


def format_table(result: BenchResult) -> str:
    """Format the benchmark table as text.

    "ours", "no-spec" and "naive" are medians of one-kind chains; "mixed" and
    "mixed mean" the median and mean of the kind's steps in the mixed chain (the
    mean also counts the steps that first build the per-pixel caches of a newly
    accepted geometry). The steps/s lines are the mixed chain's throughput and
    the naive path's, weighted by :data:`MIX`.
    """
    lines = [
        f"cores: {result.cores}  ray-cast threads: {result.threads}  "
        f"embree update: {result.update_method}  steps: {result.steps} (median)  "
        f"jax {jax.__version__}",
        f"model: {result.n_vertices} vertices, {result.n_triangles} triangles "
        f"(built in {result.build_s:.2f} s)",
        f"machine yardstick: 1-thread ray cast of the face at 250x250 {result.embree_ms:.1f} ms, "
        f"bare Embree {result.embree_bare_ms:.1f} ms "
        f"(performance-notes.md, bare Embree on its machine: 6.6 ms)",
        f"load average (1 min) before {result.load_before[0]:.2f}, "
        f"after {result.load_after[0]:.2f}",
        f"{'size':>7s} {'kind':>7s} {'ours ms':>8s} {'no-spec ms':>10s} {'spec +ms':>8s} "
        f"{'naive ms':>9s} {'naive/ours':>10s} {'face px':>7s} {'mixed ms':>8s} "
        f"{'mixed mean':>10s}",
    ]
    for r in result.rows:
        lines.append(f"{r.size:>3d}x{r.size:<3d} {r.kind:>7s} {r.ours_ms:8.2f} "
                     f"{r.ours_no_specular_ms:10.2f} {r.ours_ms - r.ours_no_specular_ms:8.2f} "
                     f"{r.naive_ms:9.1f} {r.speedup:10.1f} {r.coverage:7.1%} "
                     f"{r.mixed_ms:8.2f} {r.mixed_mean_ms:10.2f}")
    for size in dict.fromkeys(r.size for r in result.rows):
        ms = {r.kind: r for r in result.rows if r.size == size}
        if set(MIX) <= set(ms):
            mixed = sum(w * ms[k].mixed_mean_ms for k, w in MIX.items())
            naive = sum(w * ms[k].naive_mean_ms for k, w in MIX.items())
            lines.append(f"{size}x{size} mixed 40/20/20/20 (shape/pose/albedo/light): "
                         f"{1e3 / mixed:.0f} steps/s, naive {1e3 / naive:.1f} steps/s "
                         f"({naive / mixed:.0f}x)")
    lines += _against_notes(result)
    return "\n".join(lines)


#: performance-notes.md §4, ms per step with the 2-thread ray cast, on a machine whose
#: bare 1-thread Embree cast of its face at 250x250 took :data:`NOTES_EMBREE_MS`.
NOTES_STEP_MS = {
    128: {"shape": 6.4, "pose": 2.6, "albedo": 1.1, "light": 0.7},
    250: {"shape": 10.2, "pose": 6.5, "albedo": 1.7, "light": 1.1},
    512: {"shape": 23.6, "pose": 25.3, "albedo": 3.8, "light": 3.1},
}
NOTES_EMBREE_MS = 6.6


def _against_notes(result: BenchResult) -> list[str]:
    """Lines comparing the one-kind medians with the notes' figures, scaled to this machine.

    The scale is the ratio of the bare Embree casts (this machine / the notes'):
    a first-order correction for a slower or faster CPU, exact only for the
    ray-cast part of a step.
    """
    rows = [r for r in result.rows if r.size in NOTES_STEP_MS]
    if not rows or result.embree_bare_ms <= 0:
        return []
    f = result.embree_bare_ms / NOTES_EMBREE_MS
    out = [f"against performance-notes.md §4 (lower bounds measured there), scaled by this "
           f"machine's bare Embree cast: {result.embree_bare_ms:.1f} / {NOTES_EMBREE_MS} = "
           f"{f:.2f}",
           f"{'size':>7s} {'kind':>7s} {'notes ms':>8s} {'x scale':>8s} {'ours ms':>8s} "
           f"{'ours/scaled':>11s}"]
    for r in rows:
        ref = NOTES_STEP_MS[r.size][r.kind]
        out.append(f"{r.size:>3d}x{r.size:<3d} {r.kind:>7s} {ref:8.1f} {ref * f:8.2f} "
                   f"{r.ours_ms:8.2f} {r.ours_ms / (ref * f):11.2f}")
    return out
