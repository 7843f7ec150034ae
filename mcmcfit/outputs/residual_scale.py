"""How far the photographed face lies outside the model's span, read off the photograph.

The posterior predictive intervals add the model's per-vertex residual
variance ``r_v`` (what its PCA cannot represent, estimated by leave-one-out
over the training subjects) to the coefficients' posterior. A face that is
harder than the training faces (skin detail, make-up, scars: real faces, and
the evaluation's held-out subjects) lies farther outside the span than
``r_v`` says, and intervals built from ``r_v`` alone under-cover. This module
estimates, per colour channel, the scale ``s2`` for which the photographed
face's out-of-span diffuse albedo is ``N(0, s2 * r_v)`` (empirical Bayes: a
variance component estimated from the data), from the fit's own residual at
the posterior mean:

``d_p = (target_p - render_p) / g_p``, with ``g_p`` the render's derivative
with respect to the diffuse albedo at pixel ``p`` (shading times colour
gain), is the residual in albedo units: the out-of-span albedo interpolated to
the pixel, plus sensor noise divided by ``g_p``. The noise is white across
pixels; the out-of-span albedo is not: it is a per-vertex field interpolated
across the triangles, so neighbouring pixels share it. Hence the estimate uses
the covariance of neighbouring pixels' residuals, ``C1 = mean(d_p d_q)`` over
horizontally and vertically adjacent pairs, against the same covariance
``F1`` of rendered draws of a per-vertex white field ``N(0, r_v)``:
``s2 = C1 / F1``. A model without a residual variance uses ``r_v = 1``, so
``s2`` is then the out-of-span variance itself.

Pixels used: the rendered face eroded by :data:`EROSION` pixels (a silhouette
slightly off the photograph's would count background as residual), target not
near saturation, ``g_p`` at least a quarter of its median (dark, grazing
pixels amplify the noise). What the fit's image model leaves out (cast
shadows, a misfit highlight) also enters ``C1``: the intervals widen, they do
not narrow.

This module imports :mod:`albedo_model` (errors, model, params, pca,
render.renderer) and :mod:`mcmcfit.targets.image`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from scipy.ndimage import binary_erosion

from albedo_model.model import MorphableModel
from albedo_model.params import RenderParameter
from albedo_model.pca import PCAPart
from albedo_model.render.renderer import Renderer
from mcmcfit.targets.image import linearise

__all__ = ["EROSION", "ResidualEvidence", "residual_evidence", "residual_scale",
           "scale_residual_variance"]

#: Pixels taken off the rendered face's silhouette.
EROSION = 4
#: Least number of adjacent pixel pairs for an estimate.
MIN_PAIRS = 200
#: Size of the grey bump that measures the render's derivative in the albedo.
_BUMP = 0.05
#: RMS of the rendered out-of-span draws (small: the render clamps at 0 and 1).
_DRAW_RMS = 0.01


class ResidualEvidence(NamedTuple):
    """One photograph's evidence about the out-of-span albedo.

    Attributes
    ----------
    lag1 : (3,) float
        ``C1``: mean product of adjacent pixels' albedo-space residuals, per channel.
    lag1_unit : (3,) float
        ``F1``: the same for draws of out-of-span albedo ``N(0, r_v)``.
    pairs : int
        Adjacent pixel pairs averaged over.
    """

    lag1: np.ndarray
    lag1_unit: np.ndarray
    pairs: int


def _pairs(ok: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Masks of horizontally and vertically adjacent pixel pairs that are both ``ok``."""
    return ok[:, :-1] & ok[:, 1:], ok[:-1, :] & ok[1:, :]


def _adjacent(values: np.ndarray, pairs: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """Mean over the adjacent pairs of ``v_p * v_q``, per channel."""
    h, v = pairs
    total = ((values[:, :-1] * values[:, 1:])[h].sum(axis=0)
             + (values[:-1, :] * values[1:, :])[v].sum(axis=0))
    return total / max(int(h.sum() + v.sum()), 1)


def _field_model(model: MorphableModel, diffuse: np.ndarray, specular: np.ndarray | None,
                 fields: np.ndarray) -> MorphableModel:
    """Return the model whose albedo is ``diffuse + fields @ c`` (coefficients select the fields)."""
    k = fields.shape[1]
    parts = {"diffuse": PCAPart(diffuse.reshape(-1), fields, np.ones(k))}
    if model.specular is not None:
        parts["specular"] = PCAPart(np.asarray(specular, np.float64).reshape(-1),
                                    np.zeros((fields.shape[0], k)), np.ones(k))
    return dataclasses.replace(model, **parts)


def residual_evidence(model: MorphableModel, params: RenderParameter, image: np.ndarray,
                      diffuse: np.ndarray, *, specular: np.ndarray | None = None,
                      render_specular: bool = True, draws: int = 4,
                      seed: int = 0, exclude: np.ndarray | None = None,
                      shadows: bool = False) -> ResidualEvidence | None:
    """Measure a photograph's albedo-space residual at the posterior mean (see the module notes).

    Parameters
    ----------
    model : MorphableModel
        A linear-albedo model (its residual variance, or 1 per vertex when it has none).
    params : RenderParameter
        The scene at the posterior mean (its albedo coefficients are not used).
    image : (H, W, 3) float
        The photograph as fitted, gamma-encoded in [0, 1].
    diffuse, specular : (n, 3) float
        Posterior-mean albedo, linear (specular None without a specular part).
    render_specular : bool
        Render the specular term (as the fit did).
    draws : int
        Draws of the unit out-of-span field averaged for ``F1``.
    seed : int
        Seeds the draws.
    exclude : (H, W) bool, optional
        Pixels left out (what a robust fit found occluded: not out-of-span albedo).
    shadows : bool
        Cast the directional light's shadows (and scale its highlight by the
        specular albedo), as the fit's image model did: else the shadows the
        fit explained would count as out-of-span albedo.

    Returns
    -------
    ResidualEvidence or None
        None when fewer than :data:`MIN_PAIRS` adjacent pixel pairs qualify.
    """
    n = model.n_vertices
    rv = model.diffuse.residual_variance
    sd = np.sqrt(np.ones(3 * n) if rv is None else np.asarray(rv, np.float64))
    shrink = _DRAW_RMS / max(float(np.sqrt(np.mean(sd ** 2))), 1e-12)
    sd = sd * shrink  # F1 of N(0, r_v) is that of these draws / shrink^2 (linear render)
    rng = np.random.default_rng(seed)
    fields = np.column_stack([np.full(3 * n, _BUMP)]
                             + [rng.standard_normal(3 * n) * sd for _ in range(draws)])
    renderer = Renderer(_field_model(model, np.asarray(diffuse, np.float64), specular, fields),
                        specular=render_specular and model.specular is not None,
                        shadows=shadows, directional_specular_map=True)

    def render(j: int | None):
        c = np.zeros(fields.shape[1])
        if j is not None:
            c[j] = 1.0
        p = params._replace(momo=params.momo._replace(albedo=c))
        out = renderer.render(p)
        return np.asarray(out.image, np.float64), np.asarray(out.mask, bool)

    base, mask = render(None)
    gain = (render(0)[0] - base) / _BUMP
    target = linearise(np.asarray(image, np.float64)[..., :3])
    med = np.median(gain[mask], axis=0) if mask.any() else np.ones(3)
    ok = (binary_erosion(mask, iterations=EROSION) & np.all(target < 0.95, axis=-1)
          & np.all(gain > 0.25 * np.maximum(med, 1e-6), axis=-1))
    if exclude is not None:
        ok &= ~np.asarray(exclude, bool)
    adjacent = _pairs(ok)
    pairs = int(adjacent[0].sum() + adjacent[1].sum())
    if pairs < MIN_PAIRS:
        return None
    safe = np.where(ok[..., None], gain, 1.0)
    lag1 = _adjacent(np.where(ok[..., None], (target - base) / safe, 0.0), adjacent)
    unit = np.mean([_adjacent(np.where(ok[..., None], (render(j)[0] - base) / safe, 0.0),
                              adjacent)
                    for j in range(1, fields.shape[1])], axis=0) / shrink ** 2
    return ResidualEvidence(lag1, unit, pairs)


def residual_scale(evidence: Sequence[ResidualEvidence | None]) -> np.ndarray | None:
    """Pool photographs' evidence into the per-channel scale ``s2`` (>= 0), or None without any.

    Each photograph counts by its number of pixel pairs: ``s2 = sum(n C1) / sum(n F1)``.
    """
    ev = [e for e in evidence if e is not None]
    if not ev:
        return None
    num = sum(e.pairs * np.asarray(e.lag1) for e in ev)
    den = sum(e.pairs * np.asarray(e.lag1_unit) for e in ev)
    if np.any(den <= 0):
        return None
    return np.maximum(num / den, 0.0)


def scale_residual_variance(model: MorphableModel, scale: np.ndarray) -> MorphableModel:
    """Return the model whose diffuse residual variance is ``scale * r_v`` (``scale`` without ``r_v``).

    Parameters
    ----------
    model : MorphableModel
    scale : (3,) float
        Per-channel ``s2`` of :func:`residual_scale`.
    """
    part = model.diffuse
    base = (np.ones(part.dim) if part.residual_variance is None
            else np.asarray(part.residual_variance, np.float64))
    scaled = (base.reshape(-1, 3) * np.asarray(scale, np.float64)[None, :]).reshape(-1)
    return dataclasses.replace(model, diffuse=part.with_residual_variance(scaled))
