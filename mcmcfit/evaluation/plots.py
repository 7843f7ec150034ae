"""The evaluation's figures: calibration curves, and accuracy against wall time.

:func:`save_calibration` draws, per scene, the empirical coverage of the
central intervals against their nominal level (50/80/90/95 %), one line per
model (mean over the cases, bars one sd), with the diagonal and a +-7 point
band. :func:`save_accuracy_time` draws the diffuse MSE and the 90 % coverage
against the fit's wall time: at every chain checkpoint the fit recorded
(rows with ``checkpoints``: seconds, MSE, coverage), otherwise the final
point of each case.

This module imports numpy and matplotlib (Agg).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["save_accuracy_time", "save_calibration"]

_LEVELS = ("0.5", "0.8", "0.9", "0.95")


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _ok(rows: list[dict]) -> list[dict]:
    return [r for r in rows if r.get("status") == "ok" and r.get("diffuse")]


def save_calibration(rows: list[dict], path: Path) -> None:
    """Write ``calibration.png`` (see the module docstring)."""
    plt = _plt()
    ok = _ok(rows)
    scenes = list(dict.fromkeys(r["scene"] for r in rows)) or ["(none)"]
    models = list(dict.fromkeys(r["model"] for r in rows))
    fig, axes = plt.subplots(1, len(scenes), figsize=(4.2 * len(scenes), 4.2), squeeze=False)
    nominal = np.array([float(x) for x in _LEVELS])
    for ax, scene in zip(axes[0], scenes):
        ax.fill_between([0, 1], [-0.07, 0.93], [0.07, 1.07], color="0.9", label="±7 points")
        ax.plot([0, 1], [0, 1], color="0.4", lw=1, ls="--")
        for model in models:
            cov = np.array([[r["diffuse"]["coverage"][lv] for lv in _LEVELS]
                            for r in ok if r["scene"] == scene and r["model"] == model
                            and r["diffuse"].get("coverage")])
            if cov.size == 0:
                continue
            ax.errorbar(nominal, cov.mean(0), yerr=cov.std(0), marker="o", capsize=3,
                        label=f"{model} (n={len(cov)})")
        ax.set(xlim=(0.4, 1.0), ylim=(0.0, 1.02), xlabel="nominal coverage",
               ylabel="empirical coverage (diffuse)", title=f"scene {scene}")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def save_accuracy_time(rows: list[dict], path: Path) -> None:
    """Write ``accuracy_time.png`` (see the module docstring)."""
    plt = _plt()
    ok = _ok(rows)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4.2))
    keys = list(dict.fromkeys((r["scene"], r["model"]) for r in ok))
    for i, (scene, model) in enumerate(keys):
        colour = f"C{i % 10}"
        sel = [r for r in ok if r["scene"] == scene and r["model"] == model]
        label = f"{model} / {scene}"
        for r in sel:
            pts = r.get("checkpoints") or []
            if pts:
                t = [p["seconds"] for p in pts]
                a1.plot(t, [p["mse"] for p in pts], color=colour, alpha=0.6, marker=".")
                a2.plot(t, [p["coverage_90"] for p in pts], color=colour, alpha=0.6,
                        marker=".")
        t = [r["wall_s"] or np.nan for r in sel]
        a1.scatter(t, [r["diffuse"]["mse"] for r in sel], color=colour, label=label, zorder=3)
        a1.scatter(t, [r["diffuse"]["mse_model_mean"] for r in sel], color=colour,
                   marker="x", zorder=3)
        a2.scatter(t, [(r["diffuse"].get("coverage") or {}).get("0.9", np.nan) for r in sel],
                   color=colour, label=label, zorder=3)
    a1.set(xlabel="wall time of the fit (s)", ylabel="diffuse MSE (o fit, x model mean)",
           yscale="log", title="error against time")
    a2.axhline(0.9, color="0.4", ls="--", lw=1)
    a2.set(xlabel="wall time of the fit (s)", ylabel="coverage of the 90 % intervals",
           ylim=(0, 1.02), title="calibration against time")
    for ax in (a1, a2):
        ax.grid(alpha=0.3)
        if keys:
            ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
