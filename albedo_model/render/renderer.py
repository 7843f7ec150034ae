"""Rendering a model instance: cached stages driven by the blocks a change touches.

A :class:`Renderer` owns the host resources of one model (two Embree scenes for
double buffering, device copies of the triangles, transposed bases for block
updates) and turns scene parameters into a :class:`RenderState`: the per-vertex
instance, the ray-cast buffers of every pixel, and the per-pixel attributes the
shader reads (world normals, view directions, diffuse and specular albedo). The
state is immutable; :meth:`Renderer.update` returns a new one and recomputes
only the stages whose inputs a change touched (``STAGE_DEPS``):

==========================  =================================================
touched                      recomputed
==========================  =================================================
SHAPE, EXPRESSION            changed block of the instance, normals, BVH refit
                             (into the spare scene), ray cast, pixel attributes
POSE, CAMERA                 rays (transformed into the model frame), ray cast,
                             pixel attributes
ALBEDO                       changed block of the albedo instance, pixel albedo
LIGHT, COLOR_TRANSFORM, SPEC. EXP.   nothing before shading
==========================  =================================================

The light transport of every pixel (:func:`albedo_model.shading.image_formation.pixel_light`:
SH irradiance, specular lobe, directional light) is cached too and recomputed
only when the geometry, light or specular exponent changes; the image is then
``albedo x light`` plus colour transform, clamp and gamma
(:func:`albedo_model.shading.image_formation.combine_pixels`), all compiled for the scene's
effect set. The per-pixel caches are deferred
(:class:`~albedo_model.render.state.Deferred`): :meth:`Renderer.compose`,
which fuses the combination with a caller's function (a likelihood) in one
``jit``, computes the attributes a step changed inside that same loop over the
pixels without storing them (on XLA-CPU a multi-output stage costs about three
times as much), and an accepted state computes them once when a later step
reads them. A light step is thus one pass over the pixels without any gather,
an albedo step one pass with the albedo gathers, a geometry step one pass with
all gathers after the ray cast. A geometry
change is cast with the spare scene; the sampler calls :meth:`Renderer.accept`
or :meth:`Renderer.reject`, so a rejected proposal costs nothing to undo.

Work follows the face, not the image: only the rays inside the projected
bounding box of the mesh are cast (:func:`albedo_model.camera.pixel_window`),
and the per-pixel caches hold a *pixel set* (every hit plus a few misses, in
whole-row steps of 1/16 of the image: :attr:`RenderState.pixels`), so that a
face filling a third of an LFW-like image costs about a third of the per-pixel
work. :meth:`Renderer.shade` and :meth:`Renderer.image` return whole images;
:meth:`Renderer.compose` hands a likelihood the whole image or, with
``pixel_set=True``, the set itself.

This module imports only ``albedo_model`` modules.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from albedo_model.camera import (
    camera_rays, euler_rotation, eye_from_world, pixel_scale, pixel_window, principal_point_px,
)
from albedo_model.errors import InputError
from albedo_model.render.instances import ModelInstances
from albedo_model.shading.interpolation import needs_view
from albedo_model.model import MorphableModel
from albedo_model.params import Block, RenderParameter
from albedo_model.render.raycast import RayHits
from albedo_model.render.state import (
    Deferred, HostAlbedo, Rendered, RenderState, albedo_delta_stage, albedo_stage, combine_stage,
    fused_stage, geometry_stage, hits_stage, image_stage, light_effects, light_stage,
    normals_stage, pixels_satisfy,
)
from albedo_model.render.cache_table import STAGE_DEPS
from albedo_model.render.scene_slots import SceneSlots
from albedo_model.shading.image_formation import Effects, Shaded, effects_for, pack_shading_params, to_hwc
from albedo_model.render.visibility import directional_visibility, landmark_pixels

__all__ = ["Renderer", "RenderState", "Rendered", "STAGE_DEPS", "render"]



_PIXEL_BUCKETS = 16  # pixel-set capacities are multiples of 1/16 of the image's rows


def _n_pixels(state: RenderState) -> int:
    w, h = state.params.image_size
    return int(w) * int(h)


_FUSED_INPUT = {"hits": "pixel_hits", "geometry": "pixel_geometry",
                "albedo": "pixel_albedo", "light": "pixel_light"}


class Renderer:
    """Renderer of one model, with cached stages and double-buffered Embree scenes.

    Parameters
    ----------
    model : MorphableModel
    specular : bool
        Render the AlbedoMM specular term when the model has a specular part.
    gamma : bool
        Encode the output with the pure power 1/2.2 (off: linear, as fitted).
    shadows : bool
        Cast shadows of the directional light (occlusion rays; only when the
        scene has a directional light).
    background : (3,) float
        Colour of pixels without the face.
    threads : int, optional
        Ray-casting threads (1 or 2); default min(2, CPUs).
    directional_specular_map : bool
        Scale the directional light's Blinn-Phong term by the specular albedo.
    """

    def __init__(self, model: MorphableModel, *, specular: bool = True, gamma: bool = False,
                 shadows: bool = False, background=(0.0, 0.0, 0.0), threads: int | None = None,
                 directional_specular_map: bool = False):
        self.model = model
        self.specular = bool(specular and model.specular is not None)
        self.gamma = bool(gamma)
        self.shadows = bool(shadows)
        self.directional_specular_map = bool(directional_specular_map)
        self.background = tuple(float(b) for b in background)
        self._threads = threads
        self._triangles = jnp.asarray(model.triangles, jnp.int32)
        self._slots: SceneSlots | None = None
        # model-frame rays of the last cast (origins, directions), and the scene they are for
        self._rays = (np.empty((0, 3), np.float32), np.empty((0, 3), np.float32))
        self._rays_key = None
        self._views_cache: dict = {}
        self._instances = ModelInstances(model, self.specular)
        self._albedo_basis = None  # device (k, rows * 3n) transposed albedo basis, on first use
        self._capacity: dict[int, int] = {}  # pixel-set capacity per image size

    # -- effects ------------------------------------------------------------
    def effects(self, params: RenderParameter) -> Effects:
        """The effect set this renderer compiles for ``params``."""
        return effects_for(params, self.specular, shadows=self.shadows, gamma=self.gamma,
                           directional_specular_map=self.directional_specular_map)

    # -- stages ---------------------------------------------------------------
    def _albedo_update(self, state: RenderState, params: RenderParameter):
        """None when nothing changed, else ``(albedo_dev, host copy, update count)``.

        A block change is applied on the device (:func:`albedo_delta_stage`); a large
        change, or every ``refresh_every``-th update, recomputes the instance on the
        host in float64.
        """
        plan = self._instances.albedo_plan(state.params, params, state.updates[1])
        if plan is None:
            return None
        if isinstance(plan, str):
            host = self._instances.albedo(params)
            albedo_dev = jnp.asarray(host)
            return albedo_dev, HostAlbedo(albedo_dev, host), 0
        idx, delta = plan
        if self._albedo_basis is None:
            parts = self._instances.albedo_parts
            self._albedo_basis = jnp.asarray(self._instances.updater.transposed(parts))
        # one compile per block size up to 16 (a sampler uses a few fixed sizes); beyond,
        # pad to a power of two (repeating a row with zero weight) to bound recompiles
        size = len(idx) if len(idx) <= 16 else 1 << int(np.ceil(np.log2(len(idx))))
        idx = np.concatenate([idx, np.full(size - len(idx), idx[0], np.int32)])
        delta = np.concatenate([delta, np.zeros(size - len(delta), np.float32)])
        albedo_dev = albedo_delta_stage(state.albedo_dev, self._albedo_basis, idx, delta)
        return albedo_dev, HostAlbedo(albedo_dev), state.updates[1] + 1

    def _cast(self, params: RenderParameter, caster) -> RayHits:
        size = params.image_size
        w, h = int(size.width), int(size.height)
        key = (params.camera, size, params.pose, params.view)
        try:
            same = self._rays_key == key  # a shape step keeps the rays of the last cast
        except ValueError:  # array-valued fields: compare nothing, recompute
            same = False
        if not same:
            if len(self._rays[0]) != w * h:
                self._rays = (np.empty((w * h, 3), np.float32), np.empty((w * h, 3), np.float32))
            camera_rays(params.camera, size, params.pose, params.view, out=self._rays)
            self._rays_key = key
        tfar = float(params.camera.far - params.camera.near)
        # rays outside the mesh's projected bounding box cannot hit: not cast (a face
        # filling a third of an LFW-like image: 20-30 % off the ray cast)
        window = pixel_window(caster.bounds, params.camera, size, params.pose, params.view)
        return caster.cast(*self._rays, tfar=tfar, image_shape=(h, w), window=window)

    def _pixel_set(self, prim_id: np.ndarray, height: int) -> np.ndarray | None:
        """The pixels the caches of a ray cast hold (sorted indices), or None for all.

        Every hit, plus the first misses up to a capacity in steps of 1/16 of the image's rows
        (so a multiple of its width): the per-pixel programs then cost in proportion to the face
        (a face filling a third of the image: a third of the work), and compile for few shapes.
        The capacity grows when the hits outgrow it and shrinks when they fall below half of it
        (so that it does not flap between two sizes).
        """
        n_pixels = len(prim_id)
        hit = prim_id >= 0
        n = int(np.count_nonzero(hit))
        step = -(-height // _PIXEL_BUCKETS) * (n_pixels // height)  # whole rows
        cap = self._capacity.get(n_pixels)
        if cap is None or n > cap or n < cap // 2:
            cap = min(n_pixels, max(step, -(-n // step) * step))
            self._capacity[n_pixels] = cap
        if cap > n_pixels - step:
            return None
        if cap > n:
            hit = hit.copy()
            hit[np.flatnonzero(~hit)[:cap - n]] = True
        return np.flatnonzero(hit).astype(np.int32)

    def _hits_cache(self, hits: RayHits, effects: Effects, height: int):
        """(pixel set, its device copy, Deferred pixel hits) of a ray cast of ``height`` rows."""
        pixels = self._pixel_set(hits.prim_id, height)
        # whole buffers to the device (picked there: a host gather costs more);
        # device_put is several times faster than jnp.asarray for these
        prim, bary, pixels_dev = jax.device_put((hits.prim_id, hits.bary, pixels))
        px_hits = Deferred(hits_stage, {"triangles": self._triangles, "prim_id": prim,
                                        "bary": bary, "pixels": pixels_dev}, effects)
        return pixels, pixels_dev, px_hits

    def _pixels(self, params: RenderParameter, effects: Effects, normals, albedo_dev,
                px_hits: Deferred, pixels_dev):
        """Deferred (geometry, albedo) of the pixels of ``px_hits`` (pixel set ``pixels_dev``)."""
        p = params
        rotation = euler_rotation(p.pose.roll, p.pose.yaw, p.pose.pitch).astype(np.float32)
        view = self._world_views(p) if needs_view(effects) else None
        geometry = Deferred(geometry_stage(effects),
                            {"hits": px_hits, "normals": normals, "rotation": rotation,
                             "view": view, "pixels": pixels_dev}, effects)
        albedo = Deferred(albedo_stage(effects), {"hits": px_hits, "albedo_dev": albedo_dev},
                          effects)
        return geometry, albedo

    def _shading(self, params: RenderParameter) -> np.ndarray:
        p = params
        rotation = euler_rotation(p.pose.roll, p.pose.yaw, p.pose.pitch)
        return pack_shading_params(p, rotation, background=self.background)

    # -- public API -------------------------------------------------------------
    def init_state(self, params: RenderParameter) -> RenderState:
        """Compute every stage for ``params`` and make its geometry the accepted one."""
        shape = self._instances.shape(params)
        v32 = shape.reshape(-1, 3)
        vertices = jax.device_put(v32)
        normals = normals_stage(vertices, self._triangles)
        if self._slots is None:
            kw = {} if self._threads is None else {"threads": self._threads}
            self._slots = SceneSlots(v32, self.model.triangles, **kw)
        else:
            self._slots.reject()
            self._slots.current.update_vertices(v32)
        hits = self._cast(params, self._slots.current)
        albedo = self._instances.albedo(params)
        albedo_dev = jnp.asarray(albedo)
        effects = self.effects(params)
        pixels, pixels_dev, px_hits = self._hits_cache(hits, effects, params.image_size.height)
        geometry, px_albedo = self._pixels(params, effects, normals, albedo_dev, px_hits,
                                           pixels_dev)
        state = RenderState(
            params, shape, vertices, normals, albedo_dev, HostAlbedo(albedo_dev, albedo), hits,
            hits.prim_id, hits.bary, False, px_hits, geometry, px_albedo, None, effects,
            self._shading(params), (0, 0), pixels, pixels_dev,
        )
        state = state._replace(pixel_light=self._light(state, effects))
        for cache in (px_hits, geometry, px_albedo, state.pixel_light):
            cache.value  # the start of a chain: every step reuses them
        return state

    def update(self, state: RenderState, params: RenderParameter, touched: Block) -> RenderState:
        """The state for ``params``, recomputing only what ``touched`` makes stale.

        Parameters
        ----------
        state : RenderState
            The accepted state (its geometry must be the renderer's current scene).
        params : RenderParameter
            New parameters; they may differ from ``state.params`` only in ``touched``.
        touched : Block
            Blocks that changed (a proposal's declaration).

        Returns
        -------
        RenderState
            With ``geometry_pending=True`` when the geometry changed: call
            :meth:`accept` if the sampler keeps it, else :meth:`reject`.
        """
        if self._slots is None:
            raise InputError("Renderer.update needs a state from init_state first")
        s = state
        n_shape, n_albedo = s.updates
        out = {}
        caster = self._slots.current
        if touched & STAGE_DEPS["geometry"]:
            shape, n_shape = self._instances.update_shape(s.params, params, s.shape, n_shape)
            v32 = shape.reshape(-1, 3)
            vertices = jax.device_put(v32)
            out.update(shape=shape, vertices=vertices, geometry_pending=True,
                       normals=normals_stage(vertices, self._triangles))  # runs while Embree casts
            caster = self._slots.propose(v32)
        s = s._replace(params=params, **out)
        if touched & (Block.LIGHT | Block.COLOR_TRANSFORM):
            s = s._replace(effects=self.effects(params))
        if touched & STAGE_DEPS["shading"]:
            s = s._replace(shading=self._shading(params))
        effects = s.effects
        if touched & STAGE_DEPS["albedo"]:
            change = self._albedo_update(state, params)
            if change is not None:
                albedo_dev, host_albedo, n_albedo = change
                s = s._replace(albedo_dev=albedo_dev, host_albedo=host_albedo)
        s = s._replace(updates=(n_shape, n_albedo))
        if touched & STAGE_DEPS["raycast"]:
            hits = self._cast(params, caster)
            pixels, pixels_dev, px_hits = self._hits_cache(hits, effects,
                                                           params.image_size.height)
            geometry, px_albedo = self._pixels(params, effects, s.normals, s.albedo_dev, px_hits,
                                               pixels_dev)
            s = s._replace(hits=hits, prim_id=hits.prim_id, bary=hits.bary, pixel_hits=px_hits,
                           pixel_geometry=geometry, pixel_albedo=px_albedo, pixels=pixels,
                           pixels_dev=pixels_dev)
        elif not pixels_satisfy(s.pixel_geometry, s.pixel_albedo, effects):
            geometry, px_albedo = self._pixels(params, effects, s.normals, s.albedo_dev,
                                               s.pixel_hits, s.pixels_dev)
            s = s._replace(pixel_geometry=geometry, pixel_albedo=px_albedo)
        elif s.albedo_dev is not state.albedo_dev:
            s = s._replace(pixel_albedo=Deferred(
                albedo_stage(effects), {"hits": s.pixel_hits, "albedo_dev": s.albedo_dev}, effects))
        if (s.pixel_geometry is not state.pixel_geometry
                or light_effects(effects) != light_effects(state.effects)
                or touched & (Block.LIGHT | Block.SPECULAR_EXPONENT)):
            s = s._replace(pixel_light=self._light(s, effects))
        return s

    def accept(self, state: RenderState) -> RenderState:
        """Keep a proposed state: its geometry becomes the current scene."""
        if state.geometry_pending:
            self._slots.accept()
            state = state._replace(geometry_pending=False)
        return state

    def reject(self) -> None:
        """Drop a proposed state; the accepted state's buffers stay valid."""
        if self._slots is not None:
            self._slots.reject()

    @property
    def refit_supported(self) -> bool:
        """True when geometry updates refit the BVH in place (else rebuild)."""
        return self._slots is not None and self._slots.current.refit_supported

    def _light(self, state: RenderState, effects: Effects) -> Deferred:
        """Deferred light transport of ``state`` (its pixel geometry must satisfy ``effects``)."""
        shadow = self._shadow(state) if effects.shadows else None
        if shadow is not None and state.pixels is not None:
            shadow = shadow[state.pixels]
        return Deferred(light_stage(light_effects(effects)),
                        {"geometry": state.pixel_geometry, "packed": state.shading,
                         "shadow": shadow}, effects)

    def _shading_inputs(self, state: RenderState, effects: Effects | None):
        eff = state.effects if effects is None else effects
        if eff == state.effects:
            light, albedo = state.pixel_light, state.pixel_albedo
        else:  # another effect set than the cached one: compute what it needs
            if not pixels_satisfy(state.pixel_geometry, state.pixel_albedo, eff):
                geometry, albedo = self._pixels(state.params, eff, state.normals,
                                                state.albedo_dev, state.pixel_hits,
                                                state.pixels_dev)
                state = state._replace(pixel_geometry=geometry, pixel_albedo=albedo)
            light, albedo = self._light(state, eff), state.pixel_albedo
        return eff, (light.value, albedo.value, state.pixel_hits.mask, state.shading,
                     state.pixels_dev)

    def _image_inputs(self, state: RenderState) -> tuple[frozenset, dict]:
        """Which pixel attributes :func:`image_stage` computes for ``state``, and its inputs.

        Fresh deferred values are fused into the program; others are read (and
        computed first when they are not yet).
        """
        eff = state.effects
        caches = {name: getattr(state, field) for name, field in _FUSED_INPUT.items()}

        def fresh(name: str) -> bool:
            cache = caches[name]
            return not cache.computed and cache.fresh and cache.effects == eff

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
        for name in fused:
            caches[name].fresh = False
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

    def shade(self, state: RenderState, *, effects: Effects | None = None) -> Shaded:
        """Shade the state's cached pixels (device arrays; see :func:`albedo_model.shading.image_formation.shade`).

        Parameters
        ----------
        state : RenderState
        effects : Effects, optional
            Override the renderer's effect set (e.g. to compare effect costs).
        """
        eff, inputs = self._shading_inputs(state, effects)
        return combine_stage(eff, _n_pixels(state))(*inputs)

    def compose(self, fn: Callable, *, pixel_set: bool = False) -> Callable:
        """Shading fused with ``fn`` in one ``jit``: ``g(state, *args) -> fn(...)``.

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
            ``g(state, *args)``: shades ``state`` as :meth:`shade` does and applies
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
            fused, inputs = self._image_inputs(state)
            n = _n_pixels(state)
            if not fused and state.pixel_hits.computed:
                return fused_stage(state.effects, fn, n, pixel_set)(
                    inputs["light"], inputs["albedo"], state.pixel_hits.mask, inputs["packed"],
                    state.pixels_dev, *args)
            return image_stage(state.effects, fn, fused, n, pixel_set)(inputs, *args)

        return composed

    def image(self, state: RenderState) -> Rendered:
        """Shade and return host arrays ``(image (H, W, 3), mask (H, W))``."""
        out = self.shade(state)
        w, h = state.params.image_size
        image = to_hwc(out.rgb, h, w).astype(np.float32)
        mask = np.asarray(out.mask).reshape(h, w)
        return Rendered(image, mask, state)

    def render(self, params: RenderParameter) -> Rendered:
        """Full render of ``params`` (no caching across calls)."""
        return self.image(self.init_state(params))

    # -- landmarks and helpers -------------------------------------------------------
    def landmarks(self, state: RenderState, names=None) -> tuple[list[str], np.ndarray, np.ndarray]:
        """Projected landmarks of the state's instance, with visibility.

        Parameters
        ----------
        state : RenderState
        names : iterable of str, optional
            Landmark names (default: every landmark on a model vertex).

        Returns
        -------
        names : list of str
        pixels : (k, 2) float64, (x right, y down)
        visible : (k,) bool
            In front of the camera, inside the image and not occluded by the face.
        """
        caster = self._slots.candidate if state.geometry_pending else self._slots.current
        return landmark_pixels(self.model.landmark_vertices, state.shape.reshape(-1, 3),
                               state.params, caster, names)

    def _world_views(self, p: RenderParameter) -> tuple:
        """What the shader needs for each pixel's view direction (see ``render_state._views``):
        the pixel coordinates ``(x, y)`` of the image, two (H W,) device arrays cached
        per image size, and the camera as (14,) float32 (focal lengths and principal
        point in pixels, orthographic flag, world-to-eye rotation)."""
        w, h = int(p.image_size.width), int(p.image_size.height)
        if self._views_cache.get("size") != (w, h):
            ys, xs = np.divmod(np.arange(w * h, dtype=np.int64), w)
            self._views_cache = {"size": (w, h),
                                 "coords": jax.device_put((xs.astype(np.float32),
                                                           ys.astype(np.float32)))}
        fx, fy = pixel_scale(p.camera, p.image_size)
        cx, cy = principal_point_px(p.camera, p.image_size)
        r, _ = eye_from_world(p.view)
        camera = np.concatenate([[fx, fy, cx, cy, float(bool(p.camera.orthographic))],
                                 r.reshape(-1)]).astype(np.float32)
        return self._views_cache["coords"], camera

    def _shadow(self, state: RenderState) -> np.ndarray:
        p = state.params
        caster = self._slots.candidate if state.geometry_pending else self._slots.current
        return directional_visibility(state.hits, state.shape.reshape(-1, 3), self.model.triangles,
                                      p.pose, p.directional_light.direction, caster)


def render(model: MorphableModel, params: RenderParameter, *, specular: bool = True,
           gamma: bool = False, shadows: bool = False, background=(0.0, 0.0, 0.0)) -> Rendered:
    """Render one image of ``model`` with scene ``params`` (coefficients from ``params.momo``).

    Returns
    -------
    Rendered
        ``image`` (H, W, 3) float32, ``mask`` (H, W) bool and the buffers.
    """
    renderer = Renderer(model, specular=specular, gamma=gamma, shadows=shadows,
                        background=background)
    return renderer.render(params)
