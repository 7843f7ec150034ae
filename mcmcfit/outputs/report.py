"""``report.html``: one self-describing page per fit, over the PNGs beside it.

The page shows the target and the fit, the landmarks, the posterior albedo and
uncertainty maps in the fitted and the frontal view (coefficient-only std and,
for models with a residual variance, the posterior predictive std beside it),
the traces, the acceptance table per proposal, the convergence diagnostics,
the timings and provenance, and (for synthetic cases) the error against the
truth, with the coverage of both the predictive and the coefficient-only
intervals. A joint fit's page (``summary["images"]``) has a row per
photograph (its target, fit and landmarks from ``image<k>/``) and the map of
which photographs saw each vertex. Pictures are referenced by relative path,
so the folder can be moved as a whole.

This module imports only :mod:`mcmcfit.outputs.html_style`.
"""

from __future__ import annotations

import html
import math
import os
from pathlib import Path

from mcmcfit.outputs.html_style import base_css

__all__ = ["render_report", "write_report"]

_CSS = "\n" + base_css(max_width="1100px", h2_margin_top="1.6em", table_font_size="0.85em",
                       cell_padding="2px 8px") + """\
figure { display: inline-block; margin: 0.3em; vertical-align: top; text-align: center; }
figure img { max-width: 100%; image-rendering: pixelated; border: 1px solid #ddd; }
figcaption { font-size: 0.8em; color: #555; }
.small img { width: 256px; }
"""


def _fmt(v, digits: int = 4) -> str:
    if v is None:
        return "–"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, int):
        return f"{v:,}"
    if isinstance(v, float):
        if not math.isfinite(v):
            return "–"
        return f"{v:.{digits}g}"
    return html.escape(str(v))


def _table(header: list[str], rows: list[list], left: int = 1) -> str:
    th = "".join(f"<th class='l'>{html.escape(h)}</th>" if i < left else f"<th>{html.escape(h)}</th>"
                 for i, h in enumerate(header))
    body = "".join("<tr>" + "".join(
        f"<td class='l'>{_fmt(c)}</td>" if i < left else f"<td>{_fmt(c)}</td>"
        for i, c in enumerate(r)) + "</tr>" for r in rows)
    return f"<table><tr>{th}</tr>{body}</table>"


def _figure(src: str, caption: str, cls: str = "") -> str:
    return (f"<figure class='{cls}'><img src='{html.escape(src)}' alt='{html.escape(caption)}'>"
            f"<figcaption>{html.escape(caption)}</figcaption></figure>")


_REJECTIONS = ("rejected_landmarks", "rejected_prior", "rejected_image", "rejected_joint",
               "identity")


def _acceptance(stats: dict) -> str:
    rows = [[name, s.get("proposed"), s.get("accepted"), s.get("rate"),
             *(s.get(k) for k in _REJECTIONS)] for name, s in stats.items()]
    total = sum(s.get("proposed", 0) for s in stats.values())
    acc = sum(s.get("accepted", 0) for s in stats.values())
    moved = total - sum(s.get("identity", 0) for s in stats.values())
    rows.append(["all", total, acc, acc / moved if moved else None,
                 *(sum(s.get(k, 0) for s in stats.values()) for k in _REJECTIONS)])
    return _table(["proposal", "proposed", "accepted", "rate", "rejected by landmarks",
                   "by prior", "by image", "by the joint test", "identity (nothing to move)"],
                  rows)


def _truth_table(truth: dict) -> str:
    """Errors against the truth, with the coverage of both kinds of interval when known."""
    level = _fmt(100 * truth.get("interval", 0.9), 3)
    both = any("coverage_coefficients" in truth.get(p, {}) for p in ("diffuse", "specular"))
    rows, predictive = [], False
    for part in ("diffuse", "specular"):
        e = truth.get(part)
        if not e:
            continue
        row = [part, e.get("rmse"), e.get("mean_abs")]
        if both:
            predictive |= bool(e.get("predictive"))
            row += [e.get("coverage_predictive"), e.get("coverage_coefficients")]
        else:
            row.append(e.get("coverage"))
        rows.append(row)
    header = ["albedo", "RMSE", "mean |error|"]
    if both:
        header += [f"coverage, {level} % predictive", f"coverage, {level} % coefficients only"]
        note = ("predictive intervals add the model's residual variance (what it cannot "
                "represent) to the coefficients' posterior and are the headline; "
                if predictive else "the model has no residual variance, so there are no "
                "predictive intervals (–); ")
    else:
        header.append("coverage")
        note = ""
    text = (f"<p>Posterior-mean albedo against the true albedo on the "
            f"{_fmt(truth.get('n_visible'))} vertices visible in the true view (linear sRGB); "
            f"coverage: fraction of true values inside the {level} % intervals; {note}a face "
            f"drawn from the model itself lies in its span, where the coefficient-only "
            f"intervals are the ones to judge.</p>")
    return text + _table(header, rows)


def _uncertainty_note(albedo: dict) -> str:
    """One paragraph saying which standard deviations the maps show."""
    scale = (albedo.get("residual_scale") or {})
    s2 = scale.get("scale_rgb")
    if albedo.get("predictive"):
        res = (albedo.get("residual_variance") or {}).get("diffuse") or {}
        rms = ", ".join(_fmt(v, 3) for v in res.get("rms_rgb") or [])
        if s2 is not None and scale.get("base") == "unit":
            what = ("the out-of-span variance of the face, which the model does not provide, "
                    "estimated from the photograph(s) by the covariance of neighbouring "
                    "pixels' residuals (per channel R, G, B: " + ", ".join(_fmt(v, 3) for v in s2)
                    + f"; RMS {rms})")
        elif s2 is not None:
            what = ("the model's residual variance (the out-of-span variation of its training "
                    "faces, by leave-one-out) scaled to this face: the photograph(s) show "
                    + " / ".join(_fmt(v, 3) for v in s2) + " times that variance in R / G / B "
                    f"(from the covariance of neighbouring pixels' residuals; diffuse RMS {rms})")
        else:
            what = ("the model's residual variance (the out-of-span variation of faces, "
                    f"estimated by leave-one-out over the training subjects; diffuse RMS per "
                    f"channel R, G, B: {rms})")
        return ("<p>Left: the std of the coefficients' posterior alone. Right: the posterior "
                f"predictive std, which adds {what}. The intervals in posterior.npz and the "
                "coverage above are the predictive ones (the coefficient-only ones are stored "
                "beside them).</p>")
    if "predictive" in albedo:
        note = scale.get("note") or ""
        return ("<p>Coefficient-only std: the model has no residual variance (for example an "
                "AlbedoMM or BFM file) and none was estimated from the photograph"
                + (f" ({html.escape(note)})" if note else "") + ", so what the model cannot "
                "represent is not in the maps or the intervals.</p>")
    return ""


def _photographs(summary: dict, have) -> list[str]:
    """Show a joint fit's photographs: a table, then per photograph its target, fit and landmarks."""
    images = summary.get("images") or []
    rows = [[f"image{k}", im.get("image", "(array)"), im.get("landmarks"),
             im.get("visible_vertices"), im.get("landmark_rmse_px")]
            for k, im in enumerate(images)]
    parts = [f"<h2>Photographs ({len(images)}, one identity)</h2>",
             _table(["", "image", "landmarks", "vertices seen", "landmark RMSE (px)"], rows, 3)]
    for k in range(len(images)):
        parts.append(f"<h3>image{k}</h3>")
        for name, cap in (("target.png", "target"), ("fit.png", "best fit over the target"),
                          ("fit_landmarks.png", "landmarks, fit and difference")):
            if have(f"image{k}/{name}"):
                parts.append(_figure(f"image{k}/{name}", f"image{k}: {cap}",
                                     "" if name == "fit_landmarks.png" else "small"))
    return parts


def render_report(summary: dict, files: set[str] | None = None) -> str:
    """Build the report page for ``summary`` (a ``summary.json`` dict) as HTML text.

    Parameters
    ----------
    summary : dict
    files : set of str, optional
        Paths present in the folder, relative to it (``fit.png``,
        ``image0/fit.png``); pictures not in it are left out (all are assumed
        present when None).
    """
    have = (lambda name: True) if files is None else (lambda name: name in files)
    t = summary.get("timings", {})
    steps = summary.get("steps", {})
    parts = ["<!doctype html><html><head><meta charset='utf-8'>",
             "<title>mcmcfit fit report</title>", f"<style>{_CSS}</style></head><body>",
             "<h1>mcmcfit fit report</h1>"]
    conv = summary.get("convergence") or {}
    if conv and not conv.get("converged"):
        worst = ", ".join(f"{html.escape(str(w['name']))} (R-hat {_fmt(w['rhat'])}, bulk-ESS "
                          f"{_fmt(w['ess_bulk'])}, tail-ESS {_fmt(w['ess_tail'])})"
                          for w in conv.get("worst", [])[:3])
        parts.append(
            "<div style='border:3px solid #c00;background:#fee;padding:0.6em;margin:0.6em 0'>"
            "<b>The chains have NOT converged.</b> The posterior summaries, intervals and "
            "uncertainty maps below show the spread of an unconverged walk, not the posterior. "
            f"Rule: {html.escape(str(conv.get('rule')))}. Worst: {worst or 'too few draws'}. "
            "Run more steps (--steps) or more chains (--chains).</div>")
    inputs = summary.get("inputs", {})
    joint = bool(summary.get("images"))
    overview = [
        ["photographs", len(summary["images"])] if joint else
        ["image", inputs.get("image", "(array)")],
        ["landmarks", inputs.get("landmarks") or ("face box" if inputs.get("face_box") else "–")],
        ["model", summary.get("model_uri") or "–"],
        ["model sha256", summary.get("model_sha256") or "–"],
        ["model colour", (summary.get("model") or {}).get("colour_handling") or "–"],
        ["seed", summary.get("seed")],
        ["mcmcfit version", summary.get("version")],
        ["schedule", f"{steps.get('chains')} chain(s) x ({steps.get('landmark')} landmark + "
                     f"{steps.get('image')} image steps), thin {steps.get('thin')}"],
        ["time (fit, s)", t.get("total_s")],
        ["time landmark / image stage (s, summed over chains)",
         f"{_fmt(t.get('stage1_s'))} / {_fmt(t.get('stage2_s'))}"],
        ["image steps per second", t.get("stage2_steps_per_s")],
        ["landmark RMSE of the best sample (px)", summary.get("landmark_rmse_px")],
        ["landmarks used / unknown", f"{len(summary.get('landmarks', {}).get('used', []))} / "
                                     f"{', '.join(summary.get('landmarks', {}).get('unknown', [])) or '–'}"],
    ]
    parts += ["<h2>Overview</h2>", _table(["", ""], overview, left=2)]
    truth = summary.get("truth")
    if truth:
        parts += ["<h2>Error against the truth (synthetic case)</h2>", _truth_table(truth)]
        if "pose_error_deg" in truth:
            pe = truth["pose_error_deg"]
            parts.append(_table(["pose error (deg)", "yaw", "pitch", "roll"],
                                [["best sample", pe.get("yaw"), pe.get("pitch"), pe.get("roll")]]))
    if joint:
        parts += _photographs(summary, have)
    else:
        parts.append("<h2>Target and fit</h2>")
    for name, cap in (("target.png", "target"), ("fit.png", "best fit rendered over the target")):
        if have(name):
            parts.append(_figure(name, cap, "small"))
    if have("fit_landmarks.png"):
        parts.append("<br>" + _figure("fit_landmarks.png", "landmarks, fit and difference"))
    if have("occlusion.png"):
        occ = summary.get("occlusion") or {}
        share = occ.get("occluded_fraction")
        parts.append("<br>" + _figure("occlusion.png", "robust foreground: pixels the face model "
                                      "cannot explain" + ("" if share is None else
                                                         f" ({100 * share:.1f} % of the face)")))
    detection = (summary.get("inputs") or {}).get("landmark_detection")
    if detection:
        flag = (" <b>Low confidence (near profile): check the points.</b>"
                if detection.get("low_confidence") else "")
        dropped = ", ".join(detection.get("dropped", [])) or "none"
        parts.append(
            f"<h2>Detected landmarks</h2><p>{html.escape(str(detection.get('method')))}: face "
            f"{detection.get('face')} of {detection.get('n_faces')} (the largest is 0), yaw "
            f"{_fmt(detection.get('yaw_deg'))} deg estimated from the mesh; far-side points "
            f"dropped: {html.escape(dropped)}.{flag}</p>")
        if have("landmarks_detected.png"):
            parts.append(_figure("landmarks_detected.png", "detected landmarks (Basel names)"))
    for kind, title in (("albedo", "Posterior-mean albedo (display-encoded)"),
                        ("uncertainty", "Uncertainty: posterior standard deviation")):
        parts.append(f"<h2>{title}</h2>")
        if kind == "uncertainty":
            parts.append(_uncertainty_note(summary.get("albedo") or {}))
        for part in ("diffuse", "specular"):
            for view in ("fitted", "frontal"):
                name = f"{kind}_{part}_{view}.png"
                if have(name):
                    parts.append(_figure(name, f"{part}, {view} view",
                                         "small" if kind == "albedo" else ""))
            parts.append("<br>")
        if kind == "uncertainty" and have("seen_frontal.png"):
            parts.append(_figure("seen_frontal.png", "share of the photographs that saw each "
                                 "vertex (black: none; red outline on the maps above)", "small"))
    if have("traces.png"):
        parts += ["<h2>Traces</h2>", _figure("traces.png", "per-step log densities and samples")]
    parts += ["<h2>Acceptance per proposal (image stage, all chains)</h2>",
              _acceptance(summary.get("acceptance", {}))]
    if summary.get("acceptance_stage1"):
        parts += ["<h2>Acceptance per proposal (landmark stage)</h2>",
                  _acceptance(summary["acceptance_stage1"])]
    ess, rhat = summary.get("ess", {}), summary.get("rhat", {})
    parts += ["<h2>Convergence (last stage, after burn-in)</h2>",
              _table(["series", "ESS (all chains)", "split R-hat"],
                     [[k, ess.get(k), rhat.get(k)] for k in ess])]
    parts += ["<h2>Files</h2><p>" + ", ".join(
        f"<a href='{html.escape(f)}'>{html.escape(f)}</a>" for f in summary.get("files", []))
        + "</p>", "</body></html>"]
    return "\n".join(parts)


def write_report(path: str | os.PathLike, summary: dict) -> None:
    """Write ``report.html`` for ``summary`` beside the pictures it shows."""
    p = Path(path)
    files = {f.relative_to(p.parent).as_posix() for f in p.parent.rglob("*") if f.is_file()}
    p.write_text(render_report(summary, files), encoding="utf-8")
