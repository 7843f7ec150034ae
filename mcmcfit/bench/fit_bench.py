"""``mcmcfit bench fit``: the default schedule on the demo case, timed per stage and proposal kind.

The report also gives the albedo accuracy reached at checkpoints along the chain.

The demo case is :func:`mcmcfit.jobs.synthetic_case.synthetic_case` of the model
with seed 0 (250 x 250, SH light, specular, gamma). One call of
:func:`mcmcfit.fitting.fit.fit` runs; every step's wall time is recorded by the chain
recorder, so the time "after n image steps" is the setup, the landmark stage
and the first n image steps of every chain (the time a fit with
``steps=n`` would have taken, up to noise), and the accuracy there is scored
from the samples kept up to step n (after the configured burn-in fraction).

This module imports :mod:`albedo_model.model`, :mod:`mcmcfit.fitting` (config, fit,
result), :mod:`mcmcfit.jobs.synthetic_case`, :mod:`mcmcfit.outputs.accuracy` and
:mod:`mcmcfit.sampling.chain`; writing a file imports :mod:`albedo_model.io.atomic`.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from albedo_model.model import MorphableModel
from mcmcfit.fitting.fit import fit
from mcmcfit.outputs.accuracy import albedo_score, pose_error_deg
from mcmcfit.fitting.config import FitConfig
from mcmcfit.fitting.result import FitResult
from mcmcfit.jobs.synthetic_case import SyntheticCase, synthetic_case
from mcmcfit.sampling.chain import stacked_samples

__all__ = ["REFERENCE_SECONDS", "FitBench", "format_fit_bench", "plot_fit_bench",
           "proposal_kind", "run_fit_bench"]

#: The reference (scalismo-faces / AlbedoMM) pipeline's time per fit: "~20 minutes".
REFERENCE_SECONDS = 20 * 60.0

DEFAULT_CHECKPOINTS = (500, 1000, 2000, 5000, 10000)


def proposal_kind(name: str) -> str:
    """Return the kind of a proposal leaf: its name without scales and centring landmark.

    ``"albedo-0.1"`` -> ``"albedo"``, ``"focal-0.05@left.lips.corner"`` -> ``"focal"``,
    ``"sh-bands-0.1"`` -> ``"sh-bands"``.
    """
    base = name.split("@")[0]
    parts = [p for p in base.split("-") if not re.fullmatch(r"[0-9.eE+]+", p)]
    return "-".join(parts) or base


@dataclass
class FitBench:
    """Everything the benchmark measured (JSON-able through :meth:`to_dict`)."""

    config: FitConfig
    case_seed: int
    size: int
    timings: dict
    stage1_kinds: dict
    stage2_kinds: dict
    curve: list
    pose_error_landmarks_deg: float
    pose_error_best_deg: float
    reference_seconds: float = REFERENCE_SECONDS

    def to_dict(self) -> dict:
        """Return the measurements as a JSON-able dict (the config through its ``to_dict``)."""
        return {"config": self.config.to_dict(), "case_seed": self.case_seed, "size": self.size,
                "timings": self.timings, "stage1_kinds": self.stage1_kinds,
                "stage2_kinds": self.stage2_kinds, "curve": self.curve,
                "pose_error_landmarks_deg": self.pose_error_landmarks_deg,
                "pose_error_best_deg": self.pose_error_best_deg,
                "reference_seconds": self.reference_seconds,
                "speedup_vs_reference": self.reference_seconds / self.timings["total_s"]}


def _kinds(result: FitResult, stage: int) -> dict:
    """Per proposal kind: steps, seconds and accepted steps, summed over chains."""
    out: dict[str, dict] = {}
    for rec in result.records(stage):
        times = rec.time_by_proposal()
        acc = rec.acceptance()
        for name in rec.proposal_names:
            k = out.setdefault(proposal_kind(name), {"steps": 0, "seconds": 0.0, "accepted": 0})
            k["steps"] += acc[name].proposed
            k["accepted"] += acc[name].accepted
            k["seconds"] += times.get(name, 0.0)
    return dict(sorted(out.items(), key=lambda kv: -kv[1]["seconds"]))


def accuracy_curve(result: FitResult, model: MorphableModel, case: SyntheticCase,
                   checkpoints: Sequence[int]) -> list[dict]:
    """Albedo RMSE and 90 % coverage from the samples kept up to each checkpoint, with wall time."""
    recs = result.records(2)
    setup = float(result.timings.get("setup_s", 0.0))
    stage1 = [c.stage1.seconds if c.stage1 is not None else 0.0 for c in result.chains
              if c.stage2 is not None]
    burn = result.config.burn_fraction
    out = []
    for n in sorted({int(c) for c in checkpoints if 0 < int(c) <= result.config.steps}):
        samples = stacked_samples(recs, result.layout.size, discard=burn, flat=True,
                                  before_step=n)
        wall = setup + sum(stage1) + sum(float(np.sum(r.step_seconds[:n])) for r in recs)
        if samples.shape[0] == 0:
            out.append({"steps": n, "wall_s": wall, "rmse": math.nan, "coverage": math.nan,
                        "samples": 0})
            continue
        score = albedo_score(model, samples, result.layout, case.diffuse, case.visible)
        out.append({"steps": n, "wall_s": wall, "rmse": score.rmse, "coverage": score.coverage,
                    "samples": score.n_samples})
    return out


def run_fit_bench(model: MorphableModel, *, config: FitConfig | None = None, seed: int = 0,
                  case_seed: int = 0, size: int = 250,
                  checkpoints: Sequence[int] = DEFAULT_CHECKPOINTS,
                  progress: Callable | None = None) -> FitBench:
    """Fit the demo case once and measure time and accuracy.

    Parameters
    ----------
    model : MorphableModel
    config : FitConfig, optional
        Default: :class:`FitConfig` defaults (the default schedule).
    seed : int
        Seed of the fit.
    case_seed, size : int
        The synthetic case (``synthetic_case(model, seed=case_seed, size=size)``).
    checkpoints : sequence of int
        Image-stage steps at which accuracy and time are reported (those beyond
        ``config.steps`` are skipped; ``config.steps`` itself is always added).
    progress : callable ``(stage, chain, done, total)``, optional
    """
    cfg = config or FitConfig()
    case = synthetic_case(model, seed=case_seed, size=size)
    result = fit(case.image, case.landmarks, model, config=cfg, seed=seed, progress=progress)
    curve = accuracy_curve(result, model, case, [*checkpoints, cfg.steps])
    return FitBench(cfg, int(case_seed), int(size), dict(result.timings), _kinds(result, 1),
                    _kinds(result, 2), curve,
                    float(np.mean([pose_error_deg(p.pose, case.truth.pose)
                                   for p in result.lm_init])),
                    pose_error_deg(result.best.params.pose, case.truth.pose))


def format_fit_bench(b: FitBench) -> str:
    """Format the printed report of a fit benchmark."""
    t, cfg = b.timings, b.config
    lines = [
        f"fit benchmark: demo case synthetic_case(seed={b.case_seed}), {b.size}x{b.size}; "
        f"{cfg.chains} chain(s) x ({cfg.landmark_steps} landmark + {cfg.steps} image steps)",
        f"wall time {t['total_s']:.1f} s: setup {t['setup_s']:.1f} s, "
        f"stage 1 {t['stage1_s']:.1f} s "
        f"({t['stage1_steps_per_s']:.0f} steps/s), stage 2 {t['stage2_s']:.1f} s "
        f"({t['stage2_steps_per_s']:.0f} steps/s)",
        f"reference pipeline ~{b.reference_seconds / 60:.0f} min per fit: "
        f"{b.reference_seconds / t['total_s']:.1f}x faster "
        f"({100 * t['total_s'] / b.reference_seconds:.1f} % of its time)",
        f"pose error: landmark stage {b.pose_error_landmarks_deg:.2f} deg, "
        f"best sample {b.pose_error_best_deg:.2f} deg",
    ]
    for title, kinds, total in (("stage 2 (image)", b.stage2_kinds, t["stage2_s"]),
                                ("stage 1 (landmarks)", b.stage1_kinds, t["stage1_s"])):
        if not kinds:
            continue
        lines.append(f"time per proposal kind, {title}:")
        lines.append(f"  {'kind':<22}{'steps':>7}{'accepted':>10}{'seconds':>9}{'share':>8}"
                     f"{'ms/step':>9}")
        for name, k in kinds.items():
            share = k["seconds"] / total if total > 0 else math.nan
            ms = 1000 * k["seconds"] / k["steps"] if k["steps"] else math.nan
            lines.append(f"  {name:<22}{k['steps']:>7}{k['accepted']:>10}{k['seconds']:>9.2f}"
                         f"{100 * share:>7.1f}%{ms:>9.2f}")
    lines.append("accuracy vs time (posterior-mean diffuse albedo on visible vertices, "
                 "linear sRGB; coverage of the truth by the 90 % intervals):")
    lines.append(f"  {'image steps':>11}{'wall s':>9}{'RMSE':>9}{'coverage':>10}{'samples':>9}")
    for row in b.curve:
        lines.append(f"  {row['steps']:>11}{row['wall_s']:>9.1f}{row['rmse']:>9.4f}"
                     f"{100 * row['coverage']:>9.1f}%{row['samples']:>9}")
    return "\n".join(lines)


def plot_fit_bench(b: FitBench, path) -> None:
    """Write the accuracy-vs-time curve as a PNG (atomically)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from albedo_model.io.atomic import atomic_path

    wall = [r["wall_s"] for r in b.curve]
    fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=120)
    ax.plot(wall, [r["rmse"] for r in b.curve], "o-", color="tab:blue", label="albedo RMSE")
    ax.axhline(0.03, color="tab:blue", ls=":", lw=1, label="RMSE target 0.03")
    ax.set_xlabel("wall time (s)")
    ax.set_ylabel("posterior-mean albedo RMSE (linear sRGB)", color="tab:blue")
    ax.set_ylim(bottom=0)
    for r in b.curve:
        ax.annotate(f"{r['steps']}", (r["wall_s"], r["rmse"]), textcoords="offset points",
                    xytext=(4, 6), fontsize=8)
    ax2 = ax.twinx()
    ax2.plot(wall, [100 * r["coverage"] for r in b.curve], "s--", color="tab:orange",
             label="90 % interval coverage")
    ax2.axhspan(80, 98, color="tab:orange", alpha=0.08)
    ax2.set_ylabel("coverage of the truth (%)", color="tab:orange")
    ax2.set_ylim(0, 100)
    lines = ax.get_legend_handles_labels()
    lines2 = ax2.get_legend_handles_labels()
    fig.legend(lines[0] + lines2[0], lines[1] + lines2[1], fontsize=8, loc="lower center",
               ncol=3, frameon=False)
    ax.set_title(f"demo case: accuracy vs time ({b.config.chains} chain(s); labels: image steps)",
                 fontsize=9)
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)


def write_json(b: FitBench, path, *, extra: dict | None = None) -> None:
    """Write :meth:`FitBench.to_dict` (updated with ``extra``) as JSON (atomically)."""
    from albedo_model.io.atomic import atomic_path

    with atomic_path(path, suffix=".json") as tmp:
        with open(tmp, "w") as f:
            json.dump({**b.to_dict(), **(extra or {})}, f, indent=2, default=float)
