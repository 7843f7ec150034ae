"""``report.html`` of an evaluation: the table, the plots, and a row of pictures per case.

Each row shows, for one case and one model: the photograph, the fit
(``fit.png`` of its result folder), the true diffuse albedo, the posterior
mean, the absolute error (mean over R, G, B) and the posterior sd, the last
four drawn in the true view (the per-vertex values interpolated over the
true render, :func:`mcmcfit.outputs.vertex_maps.vertex_image`), with the
row's scores. Albedo pictures are gamma-encoded (1/2.2) for display; the
error and sd share one colour scale per row.

This module imports :mod:`albedo_model` (renderer, .rps), :mod:`mcmcfit.outputs`
(vertex maps) and :mod:`pipeline.synthetic.scene_render` (the truth model).
"""

from __future__ import annotations

import base64
import html
import io
from pathlib import Path

import numpy as np

__all__ = ["case_pictures", "write_report"]


def _png(array: np.ndarray) -> str:
    from PIL import Image

    a = np.asarray(array)
    if a.dtype != np.uint8:
        a = np.round(np.clip(a, 0.0, 1.0) * 255).astype(np.uint8)
    buf = io.BytesIO()
    Image.fromarray(a).save(buf, format="PNG")
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode()


def _file(path: Path) -> str | None:
    if not path.is_file():
        return None
    from PIL import Image

    with Image.open(path) as im:
        return _png(np.asarray(im.convert("RGB")))


def _heat(values: np.ndarray, mask: np.ndarray, vmax: float) -> np.ndarray:
    import matplotlib

    cmap = matplotlib.colormaps["magma"]
    rgb = cmap(np.clip(values / max(vmax, 1e-12), 0.0, 1.0))[..., :3]
    return np.where(mask[..., None], rgb, 1.0)


def case_pictures(model, truth_npz: Path, truth_rps: Path, fit_dir: Path) -> dict[str, str]:
    """Return data URLs of the true albedo, posterior mean, |error| and sd in the true view."""
    from albedo_model.io.rps import read_rps
    from albedo_model.render.renderer import Renderer
    from mcmcfit.outputs.vertex_maps import encode_display, vertex_image
    from pipeline.synthetic.scene_render import truth_model

    truth = np.load(truth_npz)
    params = read_rps(truth_rps)
    renderer = Renderer(truth_model(model, truth["diffuse"], None), specular=False, threads=1)
    state = renderer.init_state(params._replace(momo=params.momo._replace(albedo=np.zeros(1))))
    out = {}
    with np.load(fit_dir / "posterior.npz") as post:
        mean, std = post["diffuse_mean"], post["diffuse_std"]
    true_img, mask = vertex_image(state, truth["diffuse"])
    mean_img, _ = vertex_image(state, mean)
    err, _ = vertex_image(state, np.abs(mean - truth["diffuse"]).mean(axis=1))
    sd, _ = vertex_image(state, np.asarray(std).mean(axis=1))
    vmax = float(np.percentile(np.concatenate([err[mask], sd[mask]]), 99)) if mask.any() else 1.0
    white = np.ones(3)
    out["true albedo"] = _png(np.where(mask[..., None], encode_display(true_img), white))
    out["posterior mean"] = _png(np.where(mask[..., None], encode_display(mean_img), white))
    out[f"|error| (0-{vmax:.3f})"] = _png(_heat(err, mask, vmax))
    out[f"posterior sd (0-{vmax:.3f})"] = _png(_heat(sd, mask, vmax))
    return out


def _row_text(r: dict) -> str:
    d = r.get("diffuse") or {}
    cov = (d.get("coverage") or {}).get("0.9")
    floor = (r.get("projection_floor") or {}).get("diffuse")
    bits = [f"MSE {d.get('mse', float('nan')):.2e}",
            f"model mean {d.get('mse_model_mean', float('nan')):.2e}",
            f"floor {floor:.2e}" if floor is not None else "",
            f"90 % cov. {100 * cov:.0f} %" if cov is not None else "",
            f"R-hat {r['max_rhat']:.2f}" if r.get("max_rhat") else "",
            f"{r['wall_s']:.0f} s" if r.get("wall_s") else ""]
    return ", ".join(b for b in bits if b)


def write_report(root: Path, rows: list[dict], models: dict, table_md: str, path: Path) -> None:
    """Write ``report.html`` (see the module docstring).

    Parameters
    ----------
    root : Path
        The evaluation folder (cases, truth, fits).
    rows : list of dict
        Scored rows (``case``, ``model``, ``status``, scores, ``fit_dir``).
    models : dict of str to MorphableModel
        The loaded models (geometry for the true view).
    table_md : str
        ``table.md``'s text (shown as preformatted text).
    path : Path
    """
    parts = ["<!doctype html><meta charset='utf-8'><title>mcmcfit evaluate</title>",
             "<style>body{font-family:sans-serif;margin:1em}td{vertical-align:top;"
             "font-size:11px;text-align:center}img{width:128px}pre{font-size:11px}"
             ".fail{color:#b00}</style>",
             "<h1>mcmcfit evaluate: held-out albedo reconstruction</h1>",
             f"<pre>{html.escape(table_md)}</pre>"]
    for name in ("calibration.png", "accuracy_time.png"):
        url = _file(root / name)
        if url:
            parts.append(f"<h2>{name}</h2><img style='width:800px' src='{url}'>")
    parts.append("<h2>cases</h2><table>")
    geometry = next(iter(models.values()), None)
    for r in rows:
        head = f"<b>{html.escape(r['case'])}</b><br>{html.escape(r['model'])}"
        if r.get("status") != "ok":
            reason = html.escape(str(r.get("reason", "no result")))
            parts.append(f"<tr><td>{head}</td><td class='fail' colspan=6>failed: {reason}</td></tr>")
            continue
        fit_dir = root / r["fit_dir"]
        pics = {"target": _file(root / r["image"]), "fit": _file(fit_dir / "fit.png")}
        try:
            pics.update(case_pictures(geometry, root / r["truth"], root / r["truth_rps"], fit_dir))
        except Exception as exc:  # a picture that cannot be drawn must not lose the report
            pics["pictures"] = None
            head += f"<br><span class='fail'>pictures: {html.escape(str(exc))}</span>"
        cells = "".join(f"<td>{html.escape(k)}<br><img src='{v}'></td>" if v else
                        f"<td>{html.escape(k)}<br>-</td>" for k, v in pics.items())
        parts.append(f"<tr><td>{head}<br>{html.escape(_row_text(r))}</td>{cells}</tr>")
    parts.append("</table>")
    path.write_text("\n".join(parts), encoding="utf-8")
