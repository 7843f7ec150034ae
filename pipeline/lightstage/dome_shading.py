"""Shading of a mesh in the LED dome: irradiance and the specular lobe, per vertex.

The simulator renders with these functions and the processing divides by them,
so both use one definition. All LEDs are identical point sources of intensity
``I`` (spectrum and polariser folded into the colour calibration). At a vertex
``x`` with unit normal ``n`` and LED ``l`` at ``p_l``::

    E_l(x) = I max(0, n . w_l) / |p_l - x|^2 * vis_l(x),   w_l = (p_l - x) / |p_l - x|

where ``vis_l`` is 1 unless the mesh itself blocks the segment (self-shadowing:
occlusion rays, only when asked for; otherwise 1). Relative irradiance
``E(x) / E_ref`` with ``E_ref`` the irradiance of a surface at the dome
centre facing the photometric camera: a white Lambertian surface there is the
colour calibration's reference, so diffuse albedo = image / (exposure * E / E_ref).

The specular lobe is normalised Blinn-Phong summed over the LEDs, relative to
the same reference::

    L_spec(x, v) = sum_l E_l(x) / E_ref * (e + 8) / 8 * max(0, n . h_l)^e,
    h_l = (w_l + v) / |w_l + v|

(``(e + 8) / (8 pi)`` is the energy-normalising factor of Blinn-Phong; the
``1/pi`` is shared with the Lambertian term and dropped from both). A specular
albedo ``rho_s`` then appears in the image as ``exposure * rho_s * L_spec``.
Vertices facing away from the viewer get 0.

Imports only :mod:`albedo_model`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from albedo_model.errors import InputError
from albedo_model.render.raycast import RayCaster

__all__ = ["LedShading", "PixelShading", "mesh_edges", "reference_irradiance", "specular_lobe"]

#: Start of shadow rays above the surface, in mm along the normal and along the ray.
_SHADOW_OFFSET_MM = 0.05


def reference_irradiance(leds: np.ndarray, centre: np.ndarray, facing: np.ndarray,
                         intensity: float | np.ndarray = 1.0) -> float:
    """Irradiance of a surface at ``centre`` with normal ``facing`` (no occlusion), float.

    Parameters
    ----------
    leds : (L, 3) float array
    centre : (3,) float array, same frame
    facing : (3,) float array, need not be unit
    intensity : float or (L,) array
    """
    n = np.asarray(facing, float) / np.linalg.norm(facing)
    d = np.asarray(leds, float) - np.asarray(centre, float)
    r2 = np.einsum("lk,lk->l", d, d)
    cos = np.maximum(0.0, d @ n / np.sqrt(r2))
    return float(np.sum(np.asarray(intensity, float) * cos / r2))


class LedShading:
    """Per-vertex, per-LED irradiance of one mesh placement, computed once.

    Parameters
    ----------
    points : (n, 3) float array
        Vertex positions (any frame; ``leds`` in the same frame), mm.
    normals : (n, 3) float array
        Unit vertex normals.
    leds : (L, 3) float array
    reference : float
        ``E_ref`` (see :func:`reference_irradiance`).
    intensity : float or (L,) array
    caster : RayCaster, optional
        Built on the mesh in this frame: LEDs hidden by the mesh do not count
        (self-shadowing). Without it no occlusion rays are cast.
    edges : (k, 2) int array, optional
        The mesh's edges (:func:`mesh_edges`). With ``caster``: find shadow
        boundaries (see ``uncertain``).

    Attributes
    ----------
    per_led : (n, L) float64
        ``E_l / E_ref``.
    uncertain : (n, L) float64 or None
        Unshadowed ``E_l / E_ref`` of the LEDs whose visibility changes between
        this vertex and a neighbour (0 elsewhere): there a small misregistration
        of the mesh flips the shadow, so shading from these LEDs is unreliable.
        Only with ``caster`` and ``triangles``.
    points, normals, leds : arrays as given
    """

    def __init__(self, points: np.ndarray, normals: np.ndarray, leds: np.ndarray, *,
                 reference: float, intensity: float | np.ndarray = 1.0,
                 caster: RayCaster | None = None, edges: np.ndarray | None = None) -> None:
        p = np.asarray(points, float)
        nrm = np.asarray(normals, float)
        led = np.asarray(leds, float)
        if p.shape != nrm.shape or p.ndim != 2 or p.shape[1] != 3:
            raise InputError(f"points {p.shape} and normals {nrm.shape} must both be (n, 3)")
        if led.ndim != 2 or led.shape[1] != 3:
            raise InputError(f"leds must have shape (L, 3), got {led.shape}")
        if not reference > 0:
            raise InputError(f"reference irradiance must be positive, got {reference}")
        r2 = _squared_distances(p, led)
        r = np.sqrt(r2)
        cos = (nrm @ led.T - np.einsum("nk,nk->n", nrm, p)[:, None]) / r
        e = np.where(cos > 0, cos, 0.0) * (np.asarray(intensity, float) / r2)
        self.uncertain = None
        if caster is not None:
            vi, li = np.nonzero(e > 0)
            towards = (led[li] - p[vi]) / r[vi, li][:, None]
            origin = p[vi] + _SHADOW_OFFSET_MM * (nrm[vi] + towards)
            blocked = caster.occluded(origin, led[li] - origin, tmax=0.999)
            if edges is not None:
                shadow = np.zeros(e.shape, bool)
                shadow[vi[blocked], li[blocked]] = True
                self.uncertain = _shadow_boundary(shadow, e > 0, edges) * e / reference
            e[vi[blocked], li[blocked]] = 0.0
        self.per_led = e / reference
        self.points, self.normals, self.leds = p, nrm, led

    def irradiance(self) -> np.ndarray:
        """(n,) float64 relative irradiance ``E / E_ref``."""
        return self.per_led.sum(axis=1)

    def specular(self, eye: np.ndarray, exponent: float) -> np.ndarray:
        """(n,) float64 relative specular shading ``L_spec`` towards a camera centre ``eye``.

        Parameters
        ----------
        eye : (3,) float array, same frame as the points
        exponent : float
            Blinn-Phong exponent ``e``.
        """
        return specular_lobe(self.per_led, self.points, self.normals, self.leds, eye, exponent)

    def at_pixels(self, hits, eye: np.ndarray, exponent: float | None, *,
                  slope: bool = False, chunk: int = 32768) -> PixelShading:
        """Shading at the hit points of an image (per-pixel, "Phong" interpolation).

        The irradiance and the per-LED irradiance (shadows included) are
        interpolated from the vertices; the specular lobe is evaluated with the
        interpolated position and normal and the exact view and LED directions
        of each hit point. At a vertex this equals :meth:`irradiance` and
        :meth:`specular`.

        Parameters
        ----------
        hits : pipeline.lightstage.camera_render.PixelHits
            Hits on the mesh these vertices belong to.
        eye : (3,) float array
            Camera centre.
        exponent : float or None
            Blinn-Phong exponent; ``None``: no specular lobe is computed.
        slope : bool
            Also compute the lobe's sensitivity to the normal (see :func:`specular_lobe`).

        Returns
        -------
        PixelShading
        """
        irr = hits.interpolate(self.irradiance())
        lobe = irr_unc = lobe_unc = lobe_slope = None
        if self.uncertain is not None:
            irr_unc = hits.interpolate(self.uncertain.sum(axis=1))
        if exponent is not None:
            lobe, lobe_slope = self._lobe(hits, self.per_led, eye, exponent, chunk, slope)
            if self.uncertain is not None:
                lobe_unc = np.zeros(len(irr))
                near = np.flatnonzero(irr_unc > 0)
                if near.size:
                    part = type(hits)(hits.pixel[near], hits.corners[near], hits.weights[near],
                                      hits.shape)
                    lobe_unc[near] = self._lobe(part, self.uncertain, eye, exponent, chunk,
                                                False)[0]
        return PixelShading(irr, lobe, irr_unc, lobe_unc, lobe_slope)

    def _lobe(self, hits, per_led: np.ndarray, eye: np.ndarray, exponent: float,
              chunk: int, slope: bool) -> tuple[np.ndarray, np.ndarray | None]:
        out = np.empty(len(hits.pixel))
        grad = np.empty(len(hits.pixel)) if slope else None
        per_led = per_led.astype(np.float32)
        for start in range(0, len(out), chunk):
            sl = slice(start, start + chunk)
            part = type(hits)(hits.pixel[sl], hits.corners[sl], hits.weights[sl], hits.shape)
            n = part.interpolate(self.normals)
            n /= np.linalg.norm(n, axis=1, keepdims=True)
            res = specular_lobe(part.interpolate(per_led), part.interpolate(self.points),
                                n, self.leds, eye, exponent, slope=slope)
            if slope:
                out[sl], grad[sl] = res
            else:
                out[sl] = res
        return out, grad


class PixelShading(NamedTuple):
    """Shading at the hit pixels of an image (:meth:`LedShading.at_pixels`).

    Attributes
    ----------
    irradiance : (P,) float64
        ``E / E_ref``.
    lobe : (P,) float64 or None
        ``L_spec`` (None when no exponent was given).
    irradiance_uncertain, lobe_uncertain : (P,) float64 or None
        The parts of the shading from LEDs at a shadow boundary (their
        unshadowed contribution; see ``LedShading.uncertain``).
    lobe_slope : (P,) float64 or None
        Sensitivity of the lobe to the normal (when asked for).
    """

    irradiance: np.ndarray
    lobe: np.ndarray | None
    irradiance_uncertain: np.ndarray | None
    lobe_uncertain: np.ndarray | None
    lobe_slope: np.ndarray | None = None


def mesh_edges(triangles: np.ndarray) -> np.ndarray:
    """(k, 2) int64: the unique edges of a triangle mesh (smaller index first)."""
    t = np.asarray(triangles, np.int64)
    e = np.sort(np.vstack([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    return np.unique(e, axis=0)


def _shadow_boundary(shadow: np.ndarray, lit: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """(n, L) bool: the LED is shadowed at one end of a mesh edge and not at the other."""
    a, b = edges[:, 0], edges[:, 1]
    flip = (shadow[a] != shadow[b]) & lit[a] & lit[b]
    k, led = np.nonzero(flip)
    out = np.zeros(shadow.shape, bool)
    out[a[k], led] = True
    out[b[k], led] = True
    return out


def _squared_distances(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    d2 = p @ (-2.0 * q.T).astype(p.dtype)
    d2 += np.einsum("nk,nk->n", p, p)[:, None]
    d2 += np.einsum("lk,lk->l", q, q)[None, :]
    return np.maximum(d2, 1e-12, out=d2)


def specular_lobe(per_led: np.ndarray, points: np.ndarray, normals: np.ndarray,
                  leds: np.ndarray, eye: np.ndarray, exponent: float, *,
                  slope: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """``L_spec`` of surface points from their per-LED irradiance (module notes).

    Parameters
    ----------
    per_led : (P, L) float array
        ``E_l / E_ref`` (shadowing included).
    points : (P, 3) float array
    normals : (P, 3) float array
        Unit normals.
    leds : (L, 3) float array
    eye : (3,) float array
        Camera centre.
    exponent : float
        Blinn-Phong exponent ``e``.
    slope : bool
        Also return the sensitivity to the normal: ``sum_l (e + 8) / 8 E_l e
        (n . h_l)^(e - 1) |h_l x n|``, an upper bound of ``|dL_spec / dtheta|``
        for a rotation of the normal by ``theta``.

    Returns
    -------
    (P,) float64, 0 where ``n . v <= 0``; with ``slope`` a pair (lobe, slope)

    Notes
    -----
    With unit ``w_l`` (towards LED ``l``) and ``v`` (towards the camera),
    ``n . h_l = (n . w_l + n . v) / sqrt(2 + 2 w_l . v)``; all dot products
    with ``w_l`` come from (P, 3) x (3, L) products, so no (P, L, 3) array is
    formed.
    """
    e = float(exponent)
    if not e > 0:
        raise InputError(f"specular exponent must be positive, got {exponent}")
    # float32 (P, L) work: the terms are smooth and summed over a few LEDs
    p = np.asarray(points, np.float32)
    n = np.asarray(normals, np.float32)
    led = np.asarray(leds, np.float32)
    v = np.asarray(eye, np.float32)[None, :] - p
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    inv_r = 1.0 / np.sqrt(_squared_distances(p, led))
    nv = np.einsum("nk,nk->n", n, v)
    nh = n @ led.T
    nh -= np.einsum("nk,nk->n", n, p)[:, None]
    nh *= inv_r
    nh += nv[:, None]
    wv = v @ led.T
    wv -= np.einsum("nk,nk->n", v, p)[:, None]
    wv *= inv_r
    wv *= 2.0
    wv += 2.0
    np.maximum(wv, 1e-12, out=wv)
    nh /= np.sqrt(wv)
    # |n . h| <= 1 for unit vectors; the clip guards the degenerate w = -v (h undefined)
    np.clip(nh, 0.0, 1.0, out=nh)
    norm = (e + 8.0) / 8.0
    front = nv > 0
    pl = np.asarray(per_led, np.float32)
    if not slope:
        term = _power(nh, e)
        term *= pl
        return np.where(front, term.sum(axis=1, dtype=np.float64) * norm, 0.0)
    lower = _power(nh, e - 1.0) if e > 1 else np.ones_like(nh)
    lower *= pl
    out = (lower * nh).sum(axis=1, dtype=np.float64) * norm
    sine = np.sqrt(np.maximum(1.0 - nh * nh, 0.0))
    grad = (lower * sine).sum(axis=1, dtype=np.float64) * (norm * e)
    return np.where(front, out, 0.0), np.where(front, grad, 0.0)


def _power(x: np.ndarray, e: float) -> np.ndarray:
    """``x ** e`` for ``x >= 0``: repeated squaring for integer exponents (much faster)."""
    if e == int(e) and 1 <= e <= 256:
        k = int(e)
        result = None
        base = x
        while k:
            if k & 1:
                result = base.copy() if result is None else result * base
            k >>= 1
            if k:
                base = base * base
        return result
    return np.exp(e * np.log(np.maximum(x, np.finfo(x.dtype).tiny)))
