"""Does the photograph call for a directional light? Evidence from the mode of the SH-only fit.

The fit's image model starts with the SH light alone (bands 0-2: smooth
light, no hard terminator, no cast shadow). Once the chains have climbed to
its mode, :func:`directional_evidence` asks how much better the photograph is
explained when one directional light (Lambert ``max(0, n.l)`` plus a
Blinn-Phong term scaled by the specular albedo) is added: with geometry and
albedo held at the mode, the render is linear in the SH light and in the
directional light's RGB strength for a fixed direction, so every direction of
a grid over the front of the head gets an exact least-squares fit of both, per
colour channel, over the likelihood's region (colour transform inverted). The
gain in log likelihood of the best direction,
``(RSS_sh - RSS_dir) / (2 sigma^2 T)`` under the fit's noise model, is weighed
against a BIC penalty for the five extra parameters, ``2.5 log(N / T)``
(``N`` region pixels, ``T`` pixels per independent residual), plus a margin of
:data:`MARGIN` nats. No shadow ray is cast to decide: the attached shadow
(``max(0, n.l)``) alone is what SH bands 0-2 cannot make; cast shadows come
with the light once it is on.

:func:`with_directional` turns the evidence into a start: the best
direction, its strengths and the SH light fitted with it.

This module imports :mod:`albedo_model` (params, render) and
:mod:`mcmcfit.proposal_data.face_pixels`.
"""

from __future__ import annotations

import math

import numpy as np

from albedo_model.params import DirectionalLight, RenderParameter, SHLight
from albedo_model.render.light_basis import light_basis
from albedo_model.render.renderer import Renderer
from albedo_model.shading.effects import offset_count
from mcmcfit.proposal_data.face_pixels import unsaturated

__all__ = ["DIRECTIONAL_SHININESS", "MARGIN", "directional_evidence", "with_directional"]

#: Blinn-Phong exponent of the fit's directional light (held, not sampled).
DIRECTIONAL_SHININESS = 20.0

#: Nats of log likelihood beyond the BIC penalty a directional light must gain to be switched on.
MARGIN = 10.0

_AZIMUTHS = np.radians(np.arange(-80.0, 81.0, 10.0))
_ELEVATIONS = np.radians(np.arange(-30.0, 71.0, 10.0))


def _grid() -> np.ndarray:
    az, el = np.meshgrid(_AZIMUTHS, _ELEVATIONS, indexing="ij")
    az, el = az.ravel(), el.ravel()
    return np.stack([np.sin(az) * np.cos(el), np.sin(el), np.cos(az) * np.cos(el)], axis=1)


def directional_evidence(renderer: Renderer, target_linear: np.ndarray, params: RenderParameter,
                         region: np.ndarray, sigma: float, temperature: float) -> dict:
    """Compare the SH-only light with SH + one directional light at ``params`` (see the module notes).

    Parameters
    ----------
    renderer : Renderer
        The fit's renderer (its specular setting is the image model's).
    target_linear : (H, W, 3) float array
        The photograph, linearised as the likelihood reads it.
    params : RenderParameter
        The mode of the SH-only fit (its directional light is ignored).
    region : (H W,) or (H, W) bool
        The likelihood's pixels.
    sigma, temperature : float
        The noise model (pixel sd and pixels per independent residual).

    Returns
    -------
    dict
        ``gain`` (nats), ``threshold`` (nats), ``on`` (bool), ``pixels``, and the
        best candidate: ``azimuth_deg``, ``elevation_deg``, ``strength`` (RGB),
        ``sh`` ((K, 3) list, the SH light fitted with it).
    """
    p = params._replace(directional_light=DirectionalLight())
    rs = renderer.init_state(p)
    target = np.asarray(target_linear, np.float64).reshape(-1, 3)
    ok = (rs.hits.prim_id >= 0) & unsaturated(target) & np.asarray(region, bool).reshape(-1)
    face = np.flatnonzero(ok)
    basis = light_basis(rs)
    out = {"gain": 0.0, "threshold": math.inf, "on": False, "pixels": int(face.size)}
    if basis is None or face.size < 50:
        return out
    at = rs.positions(face)
    b, s = (np.asarray(x, np.float64)[at] if x is not None else None for x in basis)
    geometry, albedo = rs.pixel_geometry.value, rs.pixel_albedo.value
    normal = np.stack([np.asarray(c, np.float64)[at] for c in geometry.normal], axis=1)
    rho = np.stack([np.asarray(c, np.float64)[at] for c in albedo.diffuse], axis=1)
    spec = (np.stack([np.asarray(c, np.float64)[at] for c in albedo.specular], axis=1)
            if albedo.specular is not None and s is not None else None)
    view = (np.stack([np.asarray(c, np.float64)[at] for c in geometry.view], axis=1)
            if geometry.view is not None and spec is not None else None)
    ct = p.color_transform
    t = target[face] - np.asarray(ct.offset, np.float64) * offset_count(rs.effects)
    t = t @ np.linalg.inv(ct.matrix()).T
    dirs = _grid()
    ndl = np.maximum(normal @ dirs.T, 0.0)  # (N, D)
    blinn = None
    if view is not None:
        h = view[:, None, :] + dirs[None, :, :]
        h /= np.linalg.norm(h, axis=2, keepdims=True)
        blinn = np.maximum(np.einsum("nk,ndk->nd", normal, h), 0.0) ** DIRECTIONAL_SHININESS
    reduction = np.zeros(len(dirs))
    strength = np.zeros((3, len(dirs)))
    beta0, proj = [], []
    for c in range(3):
        x = rho[:, c:c + 1] * b + (spec[:, c:c + 1] * s if spec is not None else 0.0)
        col = rho[:, c:c + 1] * ndl + (spec[:, c:c + 1] * blinn if blinn is not None else 0.0)
        xtx = x.T @ x + 1e-8 * np.eye(x.shape[1])
        b0 = np.linalg.solve(xtx, x.T @ t[:, c])
        r0 = t[:, c] - x @ b0
        pc = np.linalg.solve(xtx, x.T @ col)  # (K, D)
        perp = col - x @ pc
        den = np.maximum(np.einsum("nd,nd->d", perp, perp), 1e-12)
        coef = (perp.T @ r0) / den
        reduction += np.where(coef > 0, coef * coef * den, 0.0)
        strength[c] = coef
        beta0.append(b0)
        proj.append(pc)
    valid = np.all(strength > 0, axis=0)
    if not valid.any():
        return out
    best = int(np.argmax(np.where(valid, reduction, -np.inf)))
    scale = 2.0 * sigma * sigma * max(1.0, temperature)
    gain = float(reduction[best] / scale)
    threshold = 2.5 * math.log(max(face.size / max(1.0, temperature), 2.0)) + MARGIN
    sh = np.stack([beta0[c] - proj[c][:, best] * strength[c, best] for c in range(3)], axis=1)
    az, el = DirectionalLight(direction=tuple(dirs[best])).angles()
    out.update(gain=gain, threshold=float(threshold), on=bool(gain > threshold),
               azimuth_deg=math.degrees(az), elevation_deg=math.degrees(el),
               strength=[float(v) for v in strength[:, best]], sh=sh.tolist())
    return out


def with_directional(params: RenderParameter, evidence: dict) -> RenderParameter:
    """Return ``params`` with the evidence's best directional light and the SH light fitted with it."""
    light = DirectionalLight.from_angles(math.radians(evidence["azimuth_deg"]),
                                         math.radians(evidence["elevation_deg"]),
                                         evidence["strength"], shininess=DIRECTIONAL_SHININESS)
    return params._replace(directional_light=light,
                           environment_map=SHLight(np.asarray(evidence["sh"], np.float64)))
