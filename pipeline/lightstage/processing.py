"""Per-subject lightstage processing: polarised images -> stitched diffuse and specular albedo.

For each photometric view (Smith et al. 2020, Sec. 2-3):

1. separation: ``D = I_perp / t``, ``S = I_para - I_perp``
   (:mod:`pipeline.lightstage.polarisation`);
2. intrinsic albedo images: the shading of the registered mesh in that view
   is rendered per pixel -- the LED irradiance ``E/E_ref`` for diffuse and
   the summed specular lobe ``L_spec`` for specular
   (:mod:`pipeline.lightstage.dome_shading`; the view's camera is calibrated in
   the mesh frame, and the LED positions are known in the photometric
   camera's frame) -- and the albedo is the least-squares ratio over a small
   window, ``a = sum(I L) / sum(L^2)``, divided by the ISO gain
   ``iso / iso_ref`` and the exposure ``kappa``. The windowed ratio is stable
   where the shading is weak (between LED highlights the specular lobe falls
   to a few per cent of its peak, and a pointwise division would amplify
   noise and misregistration there). With ``"shading": "flat"`` the
   lightstage is taken as uniform (``E = L = 1``, the paper's assumption)
   and only gain and exposure are divided out. Saturated pixels are left out;
3. sampling onto the registered mesh with visibility, cosine weights and the
   silhouette margin (:mod:`pipeline.texturing.view_sampling`);
4. the calibrated colour transform ``T = T_xyz2rgb T_raw2xyz(C) T_wb(C, e)``
   (:mod:`pipeline.lightstage.colour`) maps raw to linear sRGB.

Weights: a sample's cosine weight is multiplied by ``min(1, c / good)`` with
``c`` the window's RMS shading, so that dimly lit observations lose against
better views; below ``min_shading`` the sample is invalid. Diffuse and
specular are stitched separately (:mod:`pipeline.texturing.poisson_stitching`; reference = the
camera file's reference view, the frontal one).

This module imports :mod:`albedo_model`, :mod:`pipeline.lightstage` modules and
:mod:`pipeline.texturing` (``cameras``, ``poisson_stitching``, ``view_sampling``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from albedo_model.errors import InputError
from albedo_model.model import vertex_normals
from albedo_model.render.raycast import RayCaster
from pipeline.lightstage.colour import CameraColour
from pipeline.texturing.cameras import LightstageCamera, StitchSettings
from pipeline.lightstage.camera_render import cast_pixels
from pipeline.lightstage.dome_shading import LedShading, mesh_edges, reference_irradiance
from pipeline.lightstage.polarisation import separate_polarisation
from pipeline.texturing.poisson_stitching import stitch
from pipeline.texturing.view_sampling import bilinear_sample, sample_view

__all__ = ["ProcessingOptions", "SubjectAlbedo", "ViewAlbedo", "process_subject", "view_albedo"]


@dataclasses.dataclass(frozen=True)
class ProcessingOptions:
    """Calibration and thresholds of the processing.

    Attributes
    ----------
    colour : CameraColour
    leds_camera : (L, 3) float array
        LED positions in the photometric camera frame, mm.
    led_intensity : (L,) float array or float
    centre_camera : (3,) float array
        Dome centre in the camera frame (the ``E_ref`` reference point).
    exposure : float
        ``kappa``.
    iso_reference : float
    polariser_transmission : float
    shading : {"leds", "flat"}
    shadows : bool
    specular_exponent : float
    min_shading, min_lobe, good_shading : float
        Thresholds on the window confidence (diffuse: ``E/E_ref``; specular:
        ``L_spec``): below ``min_shading`` (diffuse) or ``min_lobe`` (specular)
        a sample is invalid, below ``good_shading`` its weight is reduced
        proportionally.
    min_cosine : float
        Samples seen at a more grazing angle (cosine between normal and view
        direction below this) are invalid.
    window_px : int
        Side of the least-squares window (1: per-pixel division).
    max_shadow_ambiguity : float
        With shadows: pixels where LEDs at a shadow boundary contribute more
        than this fraction of the shading are left out (a misregistration of
        the mesh by a fraction of a millimetre moves such boundaries).
    registration_px : float
        Expected misregistration of the mesh in pixels: pixels whose shading
        changes by much over this distance get less weight (0: no weighting).
    normal_error_rad : float
        Expected error of the mesh normals: pixels on the flanks of the specular
        lobe, whose shading changes by much for such a tilt, get less weight.
    edge_depth_mm : float
        Pixels next to a depth jump larger than this (occlusion boundaries)
        are left out.
    length_scale : float
        Unit of length for the stitching's gradients (see
        :func:`pipeline.texturing.poisson_stitching.stitch`), in mesh units (mm). With the paper's
        ``lambda = 0.1`` and millimetres the reference view's screening is
        strong enough to stop noisy gradients from drifting; rescaling the
        head to about one unit (the paper's sample mesh) gave specular errors
        about 1.5x larger on simulated captures (noise and misalignment).
    mask_scale : int
        Silhouette raster reduction (:func:`pipeline.texturing.view_sampling.sample_view`).
    """

    colour: CameraColour
    leds_camera: np.ndarray
    led_intensity: np.ndarray | float
    centre_camera: np.ndarray
    exposure: float
    iso_reference: float = 100.0
    polariser_transmission: float = 0.5
    shading: str = "leds"
    shadows: bool = True
    specular_exponent: float = 20.0
    min_shading: float = 0.05
    min_lobe: float = 0.15
    good_shading: float = 0.3
    min_cosine: float = 0.0
    window_px: int = 3
    max_shadow_ambiguity: float = 0.2
    registration_px: float = 1.0
    normal_error_rad: float = 0.015
    edge_depth_mm: float = 3.0
    length_scale: float = 1.0
    mask_scale: int = 4


class ViewAlbedo(NamedTuple):
    """One view's albedo samples on the mesh (linear sRGB).

    Attributes
    ----------
    diffuse, specular : (n, 3) float64
    diffuse_weight, specular_weight : (n,) float64
        0 where the sample is invalid.
    """

    diffuse: np.ndarray
    specular: np.ndarray
    diffuse_weight: np.ndarray
    specular_weight: np.ndarray


class SubjectAlbedo(NamedTuple):
    """Stitched albedo of one subject.

    Attributes
    ----------
    diffuse, specular : (n, 3) float64
        Linear sRGB, unclipped.
    diffuse_observed, specular_observed : (n,) bool
        Vertices with a valid sample in some view.
    diffuse_view, specular_view : (m,) int16
        Selected view per triangle (-1: none; zero gradient there).
    """

    diffuse: np.ndarray
    specular: np.ndarray
    diffuse_observed: np.ndarray
    specular_observed: np.ndarray
    diffuse_view: np.ndarray
    specular_view: np.ndarray


def _to_mesh_frame(camera: LightstageCamera, points_camera: np.ndarray) -> np.ndarray:
    return (np.asarray(points_camera, float) - camera.translation) @ camera.rotation


def _saturated(image: np.ndarray) -> np.ndarray:
    img = np.asarray(image)
    top = {np.dtype(np.uint8): 255, np.dtype(np.uint16): 65535}.get(img.dtype)
    if top is None:
        return (img >= 1.0).any(axis=2)
    return (img >= top).any(axis=2)


def _unit(image: np.ndarray) -> np.ndarray:
    img = np.asarray(image)
    scale = {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}.get(img.dtype, 1.0)
    return img.astype(np.float64) / scale


def view_albedo(parallel: np.ndarray, perpendicular: np.ndarray, camera: LightstageCamera,
                vertices: np.ndarray, triangles: np.ndarray, *, iso: float,
                options: ProcessingOptions, normals: np.ndarray | None = None,
                caster: RayCaster | None = None, edges: np.ndarray | None = None,
                boundary_distance_px: float = 100.0) -> ViewAlbedo:
    """Albedo samples of one photometric view (steps 1-4 of the module notes).

    Parameters
    ----------
    parallel, perpendicular : (H, W, 3) uint8, uint16 or float arrays
        Linear raw images.
    camera : LightstageCamera
        World = the registered mesh frame.
    vertices : (n, 3) float array
        Registered mesh, mm.
    triangles : (m, 3) int array
    iso : float
        The subject's ISO setting.
    options : ProcessingOptions
    normals, caster, edges : optional
        Shared between views (built from the mesh when omitted; ``edges``:
        :func:`pipeline.lightstage.dome_shading.mesh_edges`).
    boundary_distance_px : float

    Returns
    -------
    ViewAlbedo
    """
    v = np.asarray(vertices, float)
    tri = np.asarray(triangles)
    nrm = vertex_normals(v, tri) if normals is None else normals
    caster = RayCaster(v, tri) if caster is None else caster
    diff_img, spec_img = separate_polarisation(
        _unit(parallel), _unit(perpendicular), transmission=options.polariser_transmission)
    if diff_img.shape[:2] != tuple(camera.image_size):
        raise InputError(f"images are {diff_img.shape[1]}x{diff_img.shape[0]} pixels but the "
                         f"camera expects {camera.image_size[1]}x{camera.image_size[0]}")
    h, w = diff_img.shape[:2]
    tilt_s = np.zeros((h, w))
    if options.shading == "flat":
        shade_d = np.ones((h, w))
        shade_s = np.ones((h, w))
    else:
        leds = _to_mesh_frame(camera, options.leds_camera)
        e_ref = reference_irradiance(options.leds_camera, options.centre_camera,
                                     -np.asarray(options.centre_camera, float),
                                     options.led_intensity)
        shading = LedShading(v, nrm, leds, reference=e_ref, intensity=options.led_intensity,
                             caster=caster if options.shadows else None,
                             edges=mesh_edges(tri) if edges is None else edges)
        hits = cast_pixels(camera, caster, tri)
        px = shading.at_pixels(hits, camera.centre, options.specular_exponent, slope=True)
        irr_px, lobe_px = px.irradiance, px.lobe
        tilt = np.zeros(h * w)
        with np.errstate(divide="ignore", invalid="ignore"):
            tilt[hits.pixel] = np.where(lobe_px > 0, px.lobe_slope / lobe_px, 0.0)
        tilt_s = tilt.reshape(h, w) * options.normal_error_rad
        if px.irradiance_uncertain is not None:
            # pixels whose shading hinges on the exact shadow boundary leave the estimate
            lim = options.max_shadow_ambiguity
            irr_px = np.where(px.irradiance_uncertain > lim * irr_px, 0.0, irr_px)
            lobe_px = np.where(px.lobe_uncertain > lim * lobe_px, 0.0, lobe_px)
        shade_d, shade_s = np.zeros(h * w), np.zeros(h * w)
        shade_d[hits.pixel], shade_s[hits.pixel] = irr_px, lobe_px
        shade_d, shade_s = shade_d.reshape(h, w), shade_s.reshape(h, w)
        # next to an occlusion boundary a pixel's window would mix two surfaces
        occlusion = hits.depth_edges(options.edge_depth_mm)
        shade_d[occlusion] = 0.0
        shade_s[occlusion] = 0.0
    # saturated pixels carry no information: they leave the least-squares windows
    shade_d[_saturated(perpendicular)] = 0.0
    shade_s[_saturated(perpendicular) | _saturated(parallel)] = 0.0
    scale = options.exposure * iso / options.iso_reference
    diff_alb, conf_d = _windowed_albedo(diff_img / scale, shade_d, options.window_px,
                                        options.registration_px, 0.0)
    spec_alb, conf_s = _windowed_albedo(spec_img / scale, shade_s, options.window_px,
                                        options.registration_px, tilt_s)
    samples = sample_view(diff_alb, camera, v, tri, normals=nrm, caster=caster,
                          boundary_distance_px=boundary_distance_px,
                          mask_scale=options.mask_scale)
    uv = camera.project(v)
    spec, _ = bilinear_sample(spec_alb, uv)
    # only pixels with their own estimate count: renormalise the bilinear weights over them
    conf, _ = bilinear_sample(np.dstack([conf_d, conf_s, conf_d > 0, conf_s > 0]), uv)
    cover = np.asarray(conf[:, 2:], np.float64)
    diff_v = np.asarray(samples.colour, np.float64) / np.maximum(cover[:, :1], 1e-6)
    spec = np.asarray(spec, np.float64) / np.maximum(cover[:, 1:], 1e-6)
    conf = np.where(cover > 0.5, conf[:, :2] / np.maximum(cover, 1e-6), 0.0)
    base = samples.weight.astype(np.float64)
    t = options.colour.matrix

    def albedo(colour: np.ndarray, confidence: np.ndarray, least: float):
        ok = (base > 0) & (base >= options.min_cosine) & (confidence >= least)
        wt = np.where(ok, base * np.minimum(1.0, confidence / options.good_shading), 0.0)
        return np.where(ok[:, None], np.asarray(colour, float) @ t.T, 0.0), wt

    d, wd = albedo(diff_v, conf[:, 0], options.min_shading)
    s, ws = albedo(spec, conf[:, 1], options.min_lobe)
    return ViewAlbedo(d, s, wd, ws)


def _windowed_albedo(image: np.ndarray, shade: np.ndarray, size: int, registration_px: float,
                     tilt: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """Weighted least-squares albedo per pixel over a ``size`` x ``size`` window, and confidence.

    ``a = sum(w I L) / sum(w L^2)`` over the window (the estimate for an albedo
    that is constant in the window, image ``I = a L`` plus white noise);
    confidence ``sqrt(mean(w L^2))`` (the shading itself where it is constant
    and trusted). ``w = 1 / (1 + (d |grad ln L|)^2)`` with ``d = registration_px``
    discounts pixels whose predicted shading would change by much if the mesh
    were misregistered by ``d`` pixels (steep flanks of the specular lobe,
    shadow edges). Pixels with ``L = 0`` (background, saturation, occlusion
    edges) do not contribute and get no estimate (albedo and confidence 0).
    """
    from scipy.ndimage import uniform_filter

    spread = np.square(tilt) * np.ones_like(shade)
    if registration_px > 0:
        gy, gx = np.gradient(shade)
        with np.errstate(divide="ignore", invalid="ignore"):
            rel = np.where(shade > 0, np.hypot(gx, gy) / shade, 0.0)
        spread += (registration_px * rel) ** 2
    weight = 1.0 / (1.0 + spread)
    wl = weight * shade
    den = uniform_filter(wl * shade, size=size, mode="constant")
    num = np.stack([uniform_filter(image[..., c] * wl, size=size, mode="constant")
                    for c in range(image.shape[2])], axis=-1)
    tiny = 1e-12
    own = (shade > 0) & (den > tiny)
    alb = np.where(own[..., None], num / np.maximum(den, tiny)[..., None], 0.0)
    return alb, np.where(own, np.sqrt(np.maximum(den, 0.0)), 0.0)


def process_subject(vertices: np.ndarray, triangles: np.ndarray,
                    cameras: Sequence[LightstageCamera], parallel: Sequence[np.ndarray],
                    perpendicular: Sequence[np.ndarray], *, iso: float,
                    options: ProcessingOptions,
                    stitching: StitchSettings | None = None) -> SubjectAlbedo:
    """Stitched diffuse and specular albedo of one subject from its photometric views.

    Parameters
    ----------
    vertices : (n, 3) float array
        Registered mesh (template topology), mm.
    triangles : (m, 3) int array
    cameras : sequence of LightstageCamera, one per view (mesh frame)
    parallel, perpendicular : sequences of (H, W, 3) images, one per view
    iso : float
    options : ProcessingOptions
    stitching : StitchSettings, optional
        Silhouette margin, lambda and reference view (the capture's ``cameras.json``).

    Returns
    -------
    SubjectAlbedo
    """
    stitching = StitchSettings() if stitching is None else stitching
    if not (len(cameras) == len(parallel) == len(perpendicular)) or not cameras:
        raise InputError(f"{len(cameras)} cameras, {len(parallel)} parallel and "
                         f"{len(perpendicular)} perpendicular images: need one of each per view")
    v = np.asarray(vertices, float)
    tri = np.asarray(triangles)
    nrm = vertex_normals(v, tri)
    caster = RayCaster(v, tri)
    edges = mesh_edges(tri)
    views = [view_albedo(a, b, cam, v, tri, iso=iso, options=options, normals=nrm,
                         caster=caster, edges=edges,
                         boundary_distance_px=stitching.boundary_distance_px)
             for a, b, cam in zip(parallel, perpendicular, cameras)]
    out = {}
    for key in ("diffuse", "specular"):
        colours = np.stack([getattr(x, key) for x in views])
        weights = np.stack([getattr(x, f"{key}_weight") for x in views])
        res = stitch(v, tri, colours, weights, lam=stitching.lam,
                     reference_view=stitching.reference_view,
                     length_scale=options.length_scale)
        out[key] = (res.colour, weights.max(axis=0) > 0, res.selected_view)
    return SubjectAlbedo(out["diffuse"][0], out["specular"][0], out["diffuse"][1],
                         out["specular"][1], out["diffuse"][2], out["specular"][2])
