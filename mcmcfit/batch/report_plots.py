"""Plots of a batch report, drawn with matplotlib's Agg backend and returned as PNG bytes.

Each function takes the rows of :func:`mcmcfit.batch.report_data.batch_rows`
and draws on a fresh :class:`~matplotlib.figure.Figure` (no pyplot state).

This module imports matplotlib, NumPy and the standard library.
"""

from __future__ import annotations

import io
from collections import Counter, defaultdict

import numpy as np

__all__ = ["histogram_png", "albedo_per_subject_png", "failures_png", "MAX_SUBJECTS"]

#: Subjects shown in the albedo plot (those with the most fitted images).
MAX_SUBJECTS = 40

_GAMMA = 1.0 / 2.2


def _figure(width: float, height: float):
    from matplotlib.figure import Figure

    return Figure(figsize=(width, height), dpi=100, layout="constrained")


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def _no_data(ax, text: str = "no data") -> None:
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes, color="#777")
    ax.set_xticks([])
    ax.set_yticks([])


def histogram_png(rows: list[dict], key: str, *, xlabel: str, title: str,
                  color: str = "#4477aa") -> bytes:
    """Histogram of one numeric column over the fitted images (``status == "ok"``)."""
    values = np.array([r[key] for r in rows if r.get("status") == "ok" and r.get(key) is not None],
                      np.float64)
    fig = _figure(4.2, 3.0)
    ax = fig.add_subplot()
    if values.size:
        bins = max(5, min(40, int(np.sqrt(values.size)) * 2))
        ax.hist(values, bins=bins, color=color, edgecolor="white")
        ax.axvline(float(np.median(values)), color="#222", lw=1, ls="--",
                   label=f"median {np.median(values):.3g}")
        ax.legend(frameon=False, fontsize=8)
        ax.set_ylabel("images")
    else:
        _no_data(ax)
    ax.set_xlabel(xlabel)
    ax.set_title(title, fontsize=10)
    return _png(fig)


def albedo_per_subject_png(rows: list[dict], *, max_subjects: int = MAX_SUBJECTS) -> bytes:
    """Mean diffuse albedo (linear, mean of R, G, B over visible vertices) per image, by subject.

    One column per subject (the ``max_subjects`` with the most fitted images),
    one dot per image in the colour of its mean albedo (display-encoded), and
    a box over the images of subjects with at least three.
    """
    by_subject: dict[str, list[tuple[float, tuple]]] = defaultdict(list)
    for r in rows:
        if r.get("status") == "ok" and r.get("diffuse_mean") is not None:
            rgb = tuple(r.get(k) for k in ("diffuse_r", "diffuse_g", "diffuse_b"))
            by_subject[r["subject"]].append((r["diffuse_mean"], rgb))
    subjects = sorted(by_subject, key=lambda s: (-len(by_subject[s]), s))[:max_subjects]
    subjects.sort()
    fig = _figure(max(4.5, 0.45 * len(subjects) + 2.0), 3.4)
    ax = fig.add_subplot()
    if not subjects:
        _no_data(ax)
        return _png(fig)
    rng = np.random.default_rng(0)  # jitter only, fixed so the picture is reproducible
    for i, s in enumerate(subjects):
        vals = np.array([v for v, _ in by_subject[s]])
        if vals.size >= 3:
            ax.boxplot(vals, positions=[i], widths=0.5, showfliers=False,
                       medianprops={"color": "#444"})
        for v, rgb in by_subject[s]:
            ok = all(c is not None for c in rgb)
            colour = np.clip(np.asarray(rgb, float), 0, 1) ** _GAMMA if ok else "#888"
            ax.scatter(i + rng.uniform(-0.12, 0.12), v, s=28, color=colour, edgecolors="#333",
                       linewidths=0.5, zorder=3)
    ax.set_xticks(range(len(subjects)), subjects, rotation=60 if len(subjects) > 4 else 0,
                  ha="right" if len(subjects) > 4 else "center", fontsize=8)
    ax.set_xlim(-0.6, len(subjects) - 0.4)
    ax.set_ylabel("mean diffuse albedo\n(linear sRGB, mean of R, G, B)")
    shown = "" if len(by_subject) <= max_subjects else \
        f" ({max_subjects} of {len(by_subject)} subjects, most images first)"
    ax.set_title("posterior-mean albedo per image, by subject" + shown, fontsize=10)
    return _png(fig)


def failures_png(rows: list[dict]) -> bytes:
    """Plot counts of images per outcome: fitted, and failed / skipped by error type."""
    counts: Counter = Counter()
    for r in rows:
        if r.get("status") == "ok":
            counts["fitted"] += 1
        else:
            kind = r.get("error_type") or ""
            counts[f"{r.get('status', 'failed')}" + (f": {kind}" if kind else "")] += 1
    fig = _figure(4.8, 0.35 * max(2, len(counts)) + 1.0)
    ax = fig.add_subplot()
    if not counts:
        _no_data(ax)
        return _png(fig)
    labels = sorted(counts, key=lambda k: (k != "fitted", k))
    colours = ["#228833" if k == "fitted" else "#ccbb44" if k.startswith("skipped")
               else "#ee6677" for k in labels]
    ax.barh(range(len(labels)), [counts[k] for k in labels], color=colours)
    ax.set_yticks(range(len(labels)), labels, fontsize=8)
    ax.invert_yaxis()
    for i, k in enumerate(labels):
        ax.text(counts[k], i, f" {counts[k]}", va="center", fontsize=8)
    ax.set_xlabel("images")
    ax.set_title("outcomes", fontsize=10)
    return _png(fig)
