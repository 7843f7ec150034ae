"""Matplotlib figures of a fit: uncertainty maps with a colour bar, traces, landmarks.

Figures are drawn with the Agg backend on figure objects (no pyplot state) and
written as PNG. An uncertainty map (:func:`save_uncertainty_map`) shows the
coefficient-only posterior std and, when the model has a residual variance,
the posterior predictive std beside it, each on its own colour scale.

This module imports :mod:`mcmcfit.fitting.result` and :mod:`mcmcfit.outputs.vertex_maps`
(and matplotlib).
"""

from __future__ import annotations

import os

import numpy as np

from mcmcfit.fitting.result import FitResult
from mcmcfit.outputs.vertex_maps import std_maps, vertex_image

__all__ = ["save_scalar_map", "save_traces", "save_landmark_figure", "save_uncertainty_map",
           "uncertainty_scale"]

STD_LABEL = "posterior std of {part} albedo\n(linear sRGB, mean over R, G, B)"


def _figure(width: float, height: float):
    from matplotlib.figure import Figure

    return Figure(figsize=(width, height), dpi=100)


def save_scalar_map(path: str | os.PathLike, panels: list[tuple[str, np.ndarray, np.ndarray]], *,
                    vmax, label: str, cmap: str = "viridis",
                    outline: np.ndarray | None = None) -> None:
    """Scalar pictures side by side, on one colour scale or one each, with colour bars.

    Parameters
    ----------
    path : path-like
        PNG to write.
    panels : list of (title, image (H, W) float, mask (H, W) bool)
        Pixels outside the mask are drawn white.
    vmax : float or sequence of float
        Top of the colour scale (the bottom is 0): one for all panels (one
        colour bar), or one per panel (a colour bar each; for quantities of
        very different size, such as the coefficient-only and the predictive
        std of a sharp posterior).
    label : str
        Colour-bar label (quantity and unit).
    outline : (H, W) bool, optional
        A region drawn as a red outline on every panel.
    """
    if np.ndim(vmax):
        _separate_scales(path, panels, [float(v) for v in vmax], label, cmap, outline)
        return
    n = len(panels)
    fig = _figure(3.0 * n + 1.3, 3.4)
    right = 3.0 * n / (3.0 * n + 1.3)
    fig.subplots_adjust(left=0.02, right=right, top=0.9, bottom=0.03, wspace=0.05)
    axes = fig.subplots(1, n, squeeze=False)[0]
    im = None
    for ax, (title, img, mask) in zip(axes, panels):
        shown = np.ma.masked_array(np.asarray(img, np.float64), mask=~np.asarray(mask, bool))
        im = ax.imshow(shown, cmap=cmap, vmin=0.0, vmax=max(float(vmax), 1e-12),
                       interpolation="nearest")
        _outline(ax, outline)
        ax.set_title(title, fontsize=9)
        ax.set_axis_off()
    cax = fig.add_axes((right + 0.02, 0.1, 0.035, 0.75))
    cbar = fig.colorbar(im, cax=cax)
    cbar.set_label(label, fontsize=8)
    cbar.ax.tick_params(labelsize=7)
    fig.savefig(path)


def _outline(ax, region: np.ndarray | None) -> None:
    if region is not None and np.any(region):
        ax.contour(np.asarray(region, np.float64), levels=[0.5], colors="red", linewidths=0.8)


def _separate_scales(path, panels, vmax: list[float], label: str, cmap: str,
                     outline: np.ndarray | None = None) -> None:
    n = len(panels)
    fig = _figure(4.0 * n, 3.4)
    fig.subplots_adjust(left=0.02, right=0.9, top=0.88, bottom=0.03, wspace=0.35)
    axes = fig.subplots(1, n, squeeze=False)[0]
    for ax, (title, img, mask), top in zip(axes, panels, vmax):
        shown = np.ma.masked_array(np.asarray(img, np.float64), mask=~np.asarray(mask, bool))
        im = ax.imshow(shown, cmap=cmap, vmin=0.0, vmax=max(top, 1e-12), interpolation="nearest")
        _outline(ax, outline)
        ax.set_title(title, fontsize=9)
        ax.set_axis_off()
        cbar = fig.colorbar(im, ax=ax, fraction=0.046, pad=0.02)
        cbar.ax.tick_params(labelsize=7)
    cbar.set_label(label, fontsize=8)
    fig.savefig(path)


def uncertainty_scale(part) -> list[float]:
    """Tops of an uncertainty map's colour scales: the 99.5 % quantile of each std map."""
    return [float(np.quantile(std, 0.995)) if std.size else 1.0 for _, std in std_maps(part)]


def save_uncertainty_map(path: str | os.PathLike, state, part, *, name: str, view: str,
                         vmax: float | None = None, unseen: np.ndarray | None = None) -> None:
    """Std maps of one albedo part in one view: coefficient-only (and predictive) panels.

    Parameters
    ----------
    path : path-like
        PNG to write.
    state : albedo_model.render.renderer.RenderState
        The view (its ray hits interpolate the per-vertex values).
    part : mcmcfit.outputs.posterior.AlbedoPosterior
    name, view : str
        ``"diffuse"`` / ``"specular"`` and ``"fitted"`` / ``"frontal"``, for the titles.
    vmax : sequence of float, optional
        Colour-scale tops, one per panel, shared by the views (default
        :func:`uncertainty_scale`): the coefficient-only std of a sharp posterior
        is many times smaller than the predictive one, so each has its own scale.
    unseen : (n,) bool, optional
        Vertices no photograph saw, outlined in red (a joint fit's).
    """
    panels = []
    for label, std in std_maps(part):
        img, mask = vertex_image(state, std)
        seen = "; red: seen by no photograph" if unseen is not None else ""
        panels.append((f"{name} std, {label}\n{view} view{seen}", img, mask))
    outline = None
    if unseen is not None:
        img, mask = vertex_image(state, np.asarray(unseen, np.float64))
        outline = mask & (img > 0.5)
    save_scalar_map(path, panels, vmax=uncertainty_scale(part) if vmax is None else vmax,
                    label=STD_LABEL.format(part=name), outline=outline)


def save_traces(path: str | os.PathLike, result: FitResult,
                columns: tuple[str, ...] = ("pose.yaw", "pose.pitch", "albedo.0", "shape.0")) -> None:
    """Per-step log densities of both stages and a few sampled parameters, per chain."""
    cols = [c for c in columns if c in result.layout.names]
    fig = _figure(11.0, 5.0 if cols else 2.6)
    fig.subplots_adjust(left=0.07, right=0.99, top=0.93, bottom=0.1, wspace=0.4, hspace=0.5)
    grid = fig.subplots(2 if cols else 1, 4, squeeze=False)
    series = [(1, "landmark stage: log p + log L_lm", lambda r: r.log_posterior),
              (2, "image stage: log posterior", lambda r: r.log_posterior),
              (2, "image stage: log L_img", lambda r: r.log_lik_img),
              (2, "image stage: log L_lm", lambda r: r.log_lik_lm)]
    for ax, (stage, title, get) in zip(grid[0], series):
        recs = result.records(stage)
        if not recs:
            ax.set_visible(False)
            continue
        for ci, rec in enumerate(recs):
            y = np.asarray(get(rec), np.float64)
            x = np.arange(y.shape[0]) if rec.steps else rec.sample_step
            ax.plot(x, y, lw=0.7, label=f"chain {ci}")
        _style(ax, title)
        _robust_ylim(ax, [np.asarray(get(r), np.float64) for r in recs])
        if len(recs) > 1:
            ax.legend(fontsize=7)
    if cols:
        recs = result.records(2) or result.records(1)
        for j, ax in enumerate(grid[1]):
            if j >= len(cols) or not recs:
                ax.set_visible(False)
                continue
            k = result.layout.index(cols[j])
            for ci, rec in enumerate(recs):
                ax.plot(rec.sample_step, rec.samples[:, k], lw=0.7, label=f"chain {ci}")
            _style(ax, f"samples: {cols[j]}")
    fig.savefig(path)


def _style(ax, title: str) -> None:
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("step", fontsize=8)
    ax.tick_params(labelsize=7)


def _robust_ylim(ax, series: list[np.ndarray]) -> None:
    """Zoom on the bulk of the trace: the early burn-in can be orders of magnitude below."""
    y = np.concatenate([s[np.isfinite(s)] for s in series]) if series else np.zeros(0)
    if y.size < 10:
        return
    lo, hi = np.quantile(y, [0.05, 1.0])
    pad = 0.08 * (hi - lo) if hi > lo else 1.0
    ax.set_ylim(lo - pad, hi + pad)


def save_landmark_figure(path: str | os.PathLike, target: np.ndarray, fitted: np.ndarray,
                         fit_mask: np.ndarray, clicked: np.ndarray | None,
                         projected: np.ndarray | None) -> None:
    """Target with clicked and fitted landmarks, the fitted render, and their difference.

    Parameters
    ----------
    target, fitted : (H, W, 3) float, display-encoded
    fit_mask : (H, W) bool
        Face pixels of the fitted render.
    clicked, projected : (k, 2) pixels (x right, y down), optional
    """
    fig = _figure(9.6, 3.4)
    fig.subplots_adjust(left=0.01, right=0.94, top=0.9, bottom=0.03, wspace=0.06)
    axes = fig.subplots(1, 3)
    axes[0].imshow(np.clip(target, 0, 1), interpolation="nearest")
    if clicked is not None and len(clicked):
        axes[0].plot(clicked[:, 0], clicked[:, 1], "o", ms=4, mfc="none", mec="yellow",
                     label="target landmarks")
    if projected is not None and len(projected):
        axes[0].plot(projected[:, 0], projected[:, 1], "+", ms=6, color="red",
                     label="best fit")
    if clicked is not None or projected is not None:
        axes[0].legend(fontsize=7, loc="lower right")
    axes[0].set_title("target", fontsize=9)
    over = np.where(fit_mask[..., None], fitted, target)
    axes[1].imshow(np.clip(over, 0, 1), interpolation="nearest")
    axes[1].set_title("best fit over the target", fontsize=9)
    diff = np.abs(np.asarray(fitted, np.float64) - np.asarray(target, np.float64)).mean(-1)
    im = axes[2].imshow(np.ma.masked_array(diff, ~fit_mask), cmap="magma", vmin=0.0,
                        vmax=max(0.05, float(np.quantile(diff[fit_mask], 0.99)))
                        if fit_mask.any() else 1.0, interpolation="nearest")
    axes[2].set_title("|fit - target| (display values)", fontsize=9)
    fig.colorbar(im, ax=axes[2], fraction=0.046, pad=0.02).ax.tick_params(labelsize=7)
    for ax in axes:
        ax.set_axis_off()
    fig.savefig(path)
