"""Per-pixel work of a render: the pixel set the caches hold, what a likelihood fuses, view rays.

Work follows the face, not the image: the per-pixel caches hold a *pixel set*
(every hit plus a few misses, in whole-row steps of 1/16 of the image:
:func:`choose_pixel_set`), and :meth:`Renderer.compose
<albedo_model.render.renderer.Renderer.compose>` fuses into the likelihood's
program the pixel attributes the evaluated state created itself
(:func:`fused_inputs`).

This module imports :mod:`albedo_model.camera`, :mod:`albedo_model.params`,
:mod:`albedo_model.render.stages` and :mod:`albedo_model.render.state`.
"""

from __future__ import annotations

import numpy as np

from collections.abc import Callable

from albedo_model.camera import eye_from_world, pixel_scale, principal_point_px
from albedo_model.params import RenderParameter
from albedo_model.render.stages import fused_stage, image_stage
from albedo_model.render.state import RenderState

__all__ = ["PIXEL_BUCKETS", "choose_pixel_set", "compose", "fused_inputs", "packed_camera",
           "pixel_coordinates"]

#: Pixel-set capacities are multiples of 1/PIXEL_BUCKETS of the image's rows.
PIXEL_BUCKETS = 16

_FUSED_INPUT = {"hits": "pixel_hits", "geometry": "pixel_geometry",
                "albedo": "pixel_albedo", "light": "pixel_light"}


def choose_pixel_set(prim_id: np.ndarray, height: int,
                     capacity: int | None) -> tuple[np.ndarray | None, int]:
    """Return the pixels the caches of a ray cast hold (sorted indices, or None for all) and the capacity.

    Every hit, plus the first misses up to a capacity in steps of 1/16 of the image's rows
    (so a multiple of its width): the per-pixel programs then cost in proportion to the face
    (a face filling a third of the image: a third of the work), and compile for few shapes.
    The capacity grows when the hits outgrow it and shrinks when they fall below half of it
    (so that it does not flap between two sizes).

    Parameters
    ----------
    prim_id : (H W,) int32
        The ray cast's triangle ids (-1: miss), row-major.
    height : int
        Image rows.
    capacity : int or None
        The capacity chosen for the previous cast of this image size (None: none yet).

    Returns
    -------
    pixels : (C,) int32 or None
    capacity : int
        The capacity to pass with the next cast.
    """
    n_pixels = len(prim_id)
    hit = prim_id >= 0
    n = int(np.count_nonzero(hit))
    step = -(-height // PIXEL_BUCKETS) * (n_pixels // height)  # whole rows
    cap = capacity
    if cap is None or n > cap or n < cap // 2:
        cap = min(n_pixels, max(step, -(-n // step) * step))
    if cap > n_pixels - step:
        return None, cap
    if cap > n:
        hit = hit.copy()
        hit[np.flatnonzero(~hit)[:cap - n]] = True
    return np.flatnonzero(hit).astype(np.int32), cap


def fused_inputs(state: RenderState) -> tuple[frozenset, dict]:
    """Return which pixel attributes :func:`~albedo_model.render.stages.image_stage` computes for ``state``, and its inputs.

    Deferred values the state created itself and nothing has computed yet are fused
    into the program; others are read (and computed first when they are not yet).
    """
    eff = state.effects
    caches = {name: getattr(state, field) for name, field in _FUSED_INPUT.items()}

    def fresh(name: str) -> bool:
        cache = caches[name]
        return not cache.computed and cache.stamp == state.stamp and cache.effects == eff

    fused = set()
    if fresh("light"):
        fused.add("light")
        if fresh("geometry"):
            fused.add("geometry")
    if fresh("albedo"):
        fused.add("albedo")
    if fused & {"geometry", "albedo"} and fresh("hits"):
        fused.add("hits")
    hits, geometry, albedo, light = (caches[k] for k in ("hits", "geometry", "albedo", "light"))
    inputs = {"packed": state.shading, "prim_id": hits.inputs["prim_id"],
              "pixels": state.pixels_dev}
    if "hits" in fused:
        inputs.update(triangles=hits.inputs["triangles"], bary=hits.inputs["bary"])
    elif fused & {"geometry", "albedo"}:
        inputs["hits"] = hits.value
    if "geometry" in fused:
        inputs.update({k: geometry.inputs[k] for k in ("normals", "rotation", "view")})
    elif "light" in fused:
        inputs["geometry"] = geometry.value
    if "light" in fused:
        inputs.update(light_packed=light.inputs["packed"], shadow=light.inputs["shadow"])
    else:
        inputs["light"] = light.value
    if "albedo" in fused:
        inputs["albedo_dev"] = albedo.inputs["albedo_dev"]
    else:
        inputs["albedo"] = albedo.value
    return frozenset(fused), inputs


def pixel_coordinates(width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Return the pixel coordinates ``(x, y)`` of an image, two (H W,) float32 arrays, row-major."""
    ys, xs = np.divmod(np.arange(width * height, dtype=np.int64), width)
    return xs.astype(np.float32), ys.astype(np.float32)


def packed_camera(p: RenderParameter) -> np.ndarray:
    """Return the camera as the shader's view directions read it: (14,) float32.

    Focal lengths and principal point in pixels, the orthographic flag, and the
    world-to-eye rotation (row-major); see ``albedo_model.render.stages._views``.
    """
    fx, fy = pixel_scale(p.camera, p.image_size)
    cx, cy = principal_point_px(p.camera, p.image_size)
    r, _ = eye_from_world(p.view)
    # a far proposal (an optimiser's trial step, a diverging trajectory) can give a focal
    # length beyond float32: it becomes inf, its render non-finite and the point is refused
    with np.errstate(over="ignore"):
        return np.concatenate([[fx, fy, cx, cy, float(bool(p.camera.orthographic))],
                               r.reshape(-1)]).astype(np.float32)


def _n_pixels(state: RenderState) -> int:
    w, h = state.params.image_size
    return int(w) * int(h)


def compose(fn: Callable, *, pixel_set: bool = False) -> Callable:
    """Return shading fused with ``fn`` in one ``jit``: ``g(state, *args) -> fn(...)``.

    Parameters
    ----------
    fn : callable
        A pure JAX function of the shader output (linear unless the renderer
        gamma-encodes) and of further arguments (arrays or pytrees, e.g. a
        target image), typically a likelihood: ``fn(rgb, mask, *args)`` with
        ``rgb`` three (H W,) float32 arrays and ``mask`` (H W,) bool of the
        whole image, row-major.
    pixel_set : bool
        Call ``fn(rgb, mask, pixels, *args)`` with the shaded pixels of the
        state's pixel set instead (:attr:`RenderState.pixels`: every pixel
        whose ray hit and a few misses, ``mask`` telling which): ``rgb``
        three (C,), ``mask`` (C,), ``pixels`` (C,) int32 row-major pixel
        indices, or None when the set is the whole image (C = H W, in
        order). C is always a multiple of the image width. A face covering
        a third of the image then costs about a third of the per-pixel work
        (the whole-image form also scatters the set into the image).

    Returns
    -------
    callable
        ``g(state, *args)``: shades ``state`` as :meth:`Renderer.shade
    <albedo_model.render.renderer.Renderer.shade>` does and applies
        ``fn`` inside the same compiled function, returning ``fn``'s (device)
        result. XLA fuses the per-pixel shading into ``fn``'s reductions, so
        no image is written out; the pixel attributes the state's step
        changed and nothing has read yet (fresh :class:`Deferred` values:
        hits, geometry, albedo, light) are computed in the same loop and
        not stored. One compile per effect set, argument structure, pixel-set
        size and set of fresh attributes (a few per proposal kind): keep
        ``fn`` and the argument shapes fixed. E.g.
        ``renderer.compose(sq_error)(state, target)`` with
        ``sq_error(rgb, mask, target) = sum_c sum(where(mask, (rgb[c] - target[c])**2, 0))``.
    """
    def composed(state: RenderState, *args):
        fused, inputs = fused_inputs(state)
        n = _n_pixels(state)
        if not fused and state.pixel_hits.computed:
            return fused_stage(state.effects, fn, n, pixel_set)(
                inputs["light"], inputs["albedo"], state.pixel_hits.mask, inputs["packed"],
                state.pixels_dev, *args)
        return image_stage(state.effects, fn, fused, n, pixel_set)(inputs, *args)

    return composed
