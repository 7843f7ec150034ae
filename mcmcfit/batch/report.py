"""``mcmcfit batch-report``: one HTML page over a batch folder, and a CSV.

The page holds the counts, the plots of :mod:`mcmcfit.batch.report_plots`
(embedded as PNG data, so the page is one movable file), the failures with
their reasons, and a table with one row per image linking to the image's own
``report.html`` (relative links, valid when the page sits in OUT). The CSV has
the same rows (:data:`mcmcfit.batch.report_data.CSV_COLUMNS`).

This module imports :mod:`mcmcfit.batch.report_data`,
:mod:`mcmcfit.batch.report_plots` (matplotlib), :mod:`mcmcfit.outputs.html_style`
and, when writing, :mod:`albedo_model.io.atomic`.
"""

from __future__ import annotations

import base64
import datetime
import html
import os
from pathlib import Path

from mcmcfit.batch.report_data import batch_rows, write_csv
from mcmcfit.batch.report_plots import albedo_per_subject_png, failures_png, histogram_png
from mcmcfit.outputs.html_style import base_css

__all__ = ["render_batch_report", "write_batch_report"]

_CSS = "\n" + base_css(max_width="1200px", h2_margin_top="1.5em", table_font_size="0.8em",
                       cell_padding="2px 6px") + """\
tr.failed td { background: #fde8ea; } tr.skipped td { background: #fbf6dc; }
img.plot { margin: 0.3em; border: 1px solid #ddd; vertical-align: top; }
span.sw { display: inline-block; width: 1em; height: 1em; border: 1px solid #555;
          vertical-align: middle; }
"""


def _fmt(v, digits: int = 3) -> str:
    if v is None or v == "":
        return "–"
    if isinstance(v, float):
        return f"{v:.{digits}g}"
    return html.escape(str(v))


def _img(png: bytes, alt: str) -> str:
    data = base64.b64encode(png).decode("ascii")
    return f'<img class="plot" alt="{html.escape(alt)}" src="data:image/png;base64,{data}">'


def _swatch(row: dict) -> str:
    rgb = [row.get(k) for k in ("diffuse_r", "diffuse_g", "diffuse_b")]
    if any(c is None for c in rgb):
        return ""
    enc = [int(round(255 * min(1.0, max(0.0, c)) ** (1 / 2.2))) for c in rgb]
    return f'<span class="sw" style="background: rgb({enc[0]},{enc[1]},{enc[2]})"></span> '


def _median(rows: list[dict], key: str) -> str:
    vals = sorted(r[key] for r in rows if r.get("status") == "ok" and r.get(key) is not None)
    if not vals:
        return "–"
    n = len(vals)
    m = vals[n // 2] if n % 2 else 0.5 * (vals[n // 2 - 1] + vals[n // 2])
    return _fmt(m)


def _table(rows: list[dict], link_base: str | None) -> str:
    head = ("<tr><th class=l>subject</th><th class=l>image</th><th class=l>status</th>"
            "<th>seconds</th><th>fit s</th><th>acceptance</th><th>landmark RMS px</th>"
            "<th class=l>mean diffuse albedo (R, G, B)</th><th>albedo std</th></tr>")
    body = []
    for r in rows:
        name = html.escape(r["path"] or "")
        if r["status"] == "ok" and link_base is not None and r["relative"]:
            href = html.escape(f"{link_base}{r['relative']}/report.html", quote=True)
            name = f'<a href="{href}">{name}</a>'
        rgb = ("–" if r.get("diffuse_r") is None else _swatch(r) + ", ".join(
            f"{r[k]:.3f}" for k in ("diffuse_r", "diffuse_g", "diffuse_b")))
        status = r["status"] if r["status"] == "ok" else \
            f"{r['status']}: {html.escape(r.get('reason') or '')}"
        body.append(f'<tr class="{html.escape(r["status"])}"><td class=l>'
                    f'{html.escape(r["subject"])}</td><td class=l>{name}</td>'
                    f"<td class=l>{status}</td><td>{_fmt(r.get('seconds'))}</td>"
                    f"<td>{_fmt(r.get('fit_seconds'))}</td><td>{_fmt(r.get('acceptance'))}</td>"
                    f"<td>{_fmt(r.get('landmark_rms_px'))}</td><td class=l>{rgb}</td>"
                    f"<td>{_fmt(r.get('diffuse_std_mean'))}</td></tr>")
    return "<table>" + head + "".join(body) + "</table>"


def render_batch_report(rows: list[dict], *, title: str, link_base: str | None = "") -> str:
    """Build the HTML page for ``rows`` (:func:`mcmcfit.batch.report_data.batch_rows`).

    Parameters
    ----------
    rows : list of dict
    title : str
    link_base : str or None
        Prefix of the links to each image's ``report.html`` (``""`` when the
        page is in OUT); None: no links.
    """
    ok = [r for r in rows if r["status"] == "ok"]
    failed = [r for r in rows if r["status"] == "failed"]
    skipped = [r for r in rows if r["status"] == "skipped"]
    subjects = {r["subject"] for r in ok}
    stamp = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    parts = [
        f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
        f"<style>{_CSS}</style></head><body><h1>{html.escape(title)}</h1>",
        f"<p>{len(rows)} images: <b>{len(ok)}</b> fitted ({len(subjects)} subjects), "
        f"<b>{len(failed)}</b> failed, <b>{len(skipped)}</b> skipped. Median seconds per image "
        f"{_median(rows, 'seconds')}, acceptance {_median(rows, 'acceptance')}, landmark RMS "
        f"{_median(rows, 'landmark_rms_px')} px. Written {stamp}.</p>",
        "<h2>Plots</h2>",
        _img(histogram_png(rows, "seconds", xlabel="seconds per image (worker wall time)",
                           title="time per image"), "time per image"),
        _img(histogram_png(rows, "acceptance", xlabel="image-stage acceptance rate",
                           title="acceptance", color="#228833"), "acceptance"),
        _img(histogram_png(rows, "landmark_rms_px", xlabel="landmark RMS error of the best "
                           "sample (px)", title="landmark error", color="#aa3377"),
             "landmark error"),
        _img(failures_png(rows), "outcomes"),
        "<br>",
        _img(albedo_per_subject_png(rows), "mean albedo per subject"),
    ]
    if failed or skipped:
        parts.append("<h2>Failures and skipped images</h2><table><tr><th class=l>image</th>"
                     "<th class=l>status</th><th class=l>error</th><th class=l>reason</th></tr>")
        for r in failed + skipped:
            parts.append(f"<tr class='{html.escape(r['status'])}'><td class=l>"
                         f"{html.escape(r['path'] or '')}</td><td class=l>{r['status']}</td>"
                         f"<td class=l>{html.escape(r.get('error_type') or '')}</td>"
                         f"<td class=l>{html.escape(r.get('reason') or '')}</td></tr>")
        parts.append("</table>")
    parts += ["<h2>Images</h2>", _table(rows, link_base), "</body></html>"]
    return "\n".join(parts)


def write_batch_report(out: str | os.PathLike, html_path: str | os.PathLike, *,
                       csv_path: str | os.PathLike | None = None) -> int:
    """Write the HTML report (and the CSV) of the batch folder ``out``; return the row count.

    Links to the per-image reports are relative to the HTML file's folder.
    """
    from albedo_model.io.atomic import atomic_path

    out = Path(out)
    rows = batch_rows(out)
    target = Path(html_path)
    rel = os.path.relpath(out.absolute(), target.absolute().parent).replace(os.sep, "/")
    link_base = "" if rel == "." else rel + "/"
    page = render_batch_report(rows, title=f"mcmcfit batch report: {out.name}",
                               link_base=link_base)
    with atomic_path(target) as tmp:
        tmp.write_text(page, encoding="utf-8")
    if csv_path is not None:
        write_csv(rows, csv_path)
    return len(rows)
