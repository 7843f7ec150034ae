"""Rendering a model instance: cached stages driven by the blocks a change touches.

A :class:`Renderer` owns the host resources of one model (two Embree scenes for
double buffering, device copies of the triangles, transposed bases for block
updates) and turns scene parameters into a :class:`RenderState`: the per-vertex
instance, the ray-cast buffers of every pixel, and the per-pixel attributes the
shader reads. The state is immutable; :meth:`Renderer.update` returns a new one
and recomputes only the stages whose blocks a change touched, as the one table
:data:`albedo_model.render.cache_table.STAGE_DEPS` says (geometry: the changed
block of the instance, normals and the BVH refit into the spare scene; raycast:
rays, ray cast and pixel attributes; albedo: the changed block of the albedo
instance and the pixel albedo; light, colour transform and specular exponent:
nothing before shading). Each state carries the version stamps of its blocks,
on which the caches outside it (the ray buffer here, the proposals' data) are
keyed.

The per-pixel light transport (SH irradiance, specular lobe, directional
light) is cached too; the image is ``albedo x light`` plus colour transform,
clamp and gamma, compiled for the scene's effect set. The per-pixel caches are
deferred (:class:`~albedo_model.render.state.Deferred`): :meth:`Renderer.compose`
fuses the attributes a step changed into the likelihood's program without
storing them, and an accepted state computes them when a later step reads
them. A geometry change is cast with the spare scene; the sampler calls
:meth:`Renderer.accept` or :meth:`Renderer.reject`, so a rejected proposal
costs nothing to undo. Only the rays inside the projected bounding box of the
mesh are cast, and the caches hold a pixel set
(:mod:`albedo_model.render.pixel_work`): work follows the face, not the image.

This module imports :mod:`albedo_model` (camera, errors, model, params), the
:mod:`albedo_model.render` modules but embree_refit, normals and ray_batches, and
:mod:`albedo_model.shading` (image_formation, interpolation).
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from albedo_model.camera import camera_rays, euler_rotation, pixel_window
from albedo_model.errors import InputError
from albedo_model.render.instances import ModelInstances
from albedo_model.shading.interpolation import needs_view
from albedo_model.model import MorphableModel
from albedo_model.params import Block, RenderParameter
from albedo_model.render.raycast import RayHits
from albedo_model.render.stages import (
    albedo_stage, combine_stage, geometry_stage, hits_stage,
    light_effects, light_stage, normals_stage, pixels_satisfy,
)
from albedo_model.render.state import Deferred, HostAlbedo, Rendered, RenderState
from albedo_model.render.cache_table import (
    BlockVersions, bump, new_stamp, new_versions, stage_key, stale)
from albedo_model.render.albedo_updates import DeviceAlbedo
from albedo_model.render.pixel_work import (
    choose_pixel_set, compose, packed_camera, pixel_coordinates)
from albedo_model.render.scene_slots import SceneSlots
from albedo_model.shading.image_formation import Effects, Shaded, effects_for, pack_shading_params, to_hwc
from albedo_model.render.shadows import state_shadow
from albedo_model.render.visibility import landmark_pixels

__all__ = ["Renderer", "RenderState", "Rendered", "render"]


def _n_pixels(state: RenderState) -> int:
    w, h = state.params.image_size
    return int(w) * int(h)


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
    shadow_rays, shadow_spread_deg : int, float
        Shadow rays per face pixel and the light's angular radius they sample
        (1 ray: hard shadows; more: soft edges).
    """

    def __init__(self, model: MorphableModel, *, specular: bool = True, gamma: bool = False,
                 shadows: bool = False, background=(0.0, 0.0, 0.0), threads: int | None = None,
                 directional_specular_map: bool = False, shadow_rays: int = 1,
                 shadow_spread_deg: float = 3.0):
        if not (isinstance(shadow_rays, int) and shadow_rays >= 1):
            raise InputError(f"shadow_rays must be an integer >= 1, got {shadow_rays!r}")
        self.model, self._threads = model, threads
        self.specular = bool(specular and model.specular is not None)
        self.gamma, self.shadows = bool(gamma), bool(shadows)
        self.directional_specular_map = bool(directional_specular_map)
        self.shadow_rays, self.shadow_spread_deg = shadow_rays, float(shadow_spread_deg)
        self.background = tuple(float(b) for b in background)
        self._triangles = jnp.asarray(model.triangles, jnp.int32)
        self._slots: SceneSlots | None = None
        # model-frame rays of the last cast (origins, directions), and the scene they are for
        self._rays = (np.empty((0, 3), np.float32), np.empty((0, 3), np.float32))
        self._rays_key = None
        self._views_cache: dict = {}
        self._instances = ModelInstances(model, self.specular)
        self._device_albedo = DeviceAlbedo(self._instances)
        self._capacity: dict[int, int] = {}  # pixel-set capacity per image size
        #: Rays cast so far: ``primary`` (camera rays) and ``shadow`` (towards the light).
        self.ray_counts = {"primary": 0, "shadow": 0}

    # -- effects ------------------------------------------------------------
    def effects(self, params: RenderParameter) -> Effects:
        """Return the effect set this renderer compiles for ``params``."""
        return effects_for(params, self.specular, shadows=self.shadows, gamma=self.gamma,
                           directional_specular_map=self.directional_specular_map)

    def _cast(self, params: RenderParameter, caster, versions: BlockVersions) -> RayHits:
        size = params.image_size
        w, h = int(size.width), int(size.height)
        # the rays of the last cast serve while pose and camera keep their stamps (a shape
        # step); view and image size are never proposed, compared by value
        key = (stage_key(versions, "rays"), tuple(size), tuple(params.view))
        if self._rays_key != key:
            if len(self._rays[0]) != w * h:
                self._rays = (np.empty((w * h, 3), np.float32), np.empty((w * h, 3), np.float32))
            camera_rays(params.camera, size, params.pose, params.view, out=self._rays)
            self._rays_key = key
        tfar = float(params.camera.far - params.camera.near)
        # rays outside the mesh's projected bounding box cannot hit: not cast (a face
        # filling a third of an LFW-like image: 20-30 % off the ray cast)
        window = pixel_window(caster.bounds, params.camera, size, params.pose, params.view)
        y0, y1, x0, x1 = window if window is not None else (0, h, 0, w)
        self.ray_counts["primary"] += max(0, y1 - y0) * max(0, x1 - x0)
        return caster.cast(*self._rays, tfar=tfar, image_shape=(h, w), window=window)

    def _hits_cache(self, hits: RayHits, effects: Effects, height: int, stamp: int):
        """(pixel set, its device copy, Deferred pixel hits) of a ray cast of ``height`` rows."""
        n_pixels = len(hits.prim_id)
        pixels, self._capacity[n_pixels] = choose_pixel_set(
            hits.prim_id, height, self._capacity.get(n_pixels))
        # whole buffers to the device (picked there: a host gather costs more);
        # device_put is several times faster than jnp.asarray for these
        prim, bary, pixels_dev = jax.device_put((hits.prim_id, hits.bary, pixels))
        px_hits = Deferred(hits_stage, {"triangles": self._triangles, "prim_id": prim,
                                        "bary": bary, "pixels": pixels_dev}, effects, stamp)
        return pixels, pixels_dev, px_hits

    def _pixels(self, params: RenderParameter, effects: Effects, normals, albedo_dev,
                px_hits: Deferred, pixels_dev, stamp: int):
        """Deferred (geometry, albedo) of the pixels of ``px_hits`` (pixel set ``pixels_dev``)."""
        p = params
        rotation = euler_rotation(p.pose.roll, p.pose.yaw, p.pose.pitch).astype(np.float32)
        view = self._world_views(p) if needs_view(effects) else None
        geometry = Deferred(geometry_stage(effects),
                            {"hits": px_hits, "normals": normals, "rotation": rotation,
                             "view": view, "pixels": pixels_dev}, effects, stamp)
        albedo = Deferred(albedo_stage(effects), {"hits": px_hits, "albedo_dev": albedo_dev},
                          effects, stamp)
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
        versions, stamp = new_versions(), new_stamp()
        hits = self._cast(params, self._slots.current, versions)
        albedo = self._instances.albedo(params)
        albedo_dev = jnp.asarray(albedo)
        effects = self.effects(params)
        pixels, pixels_dev, px_hits = self._hits_cache(hits, effects, params.image_size.height,
                                                       stamp)
        geometry, px_albedo = self._pixels(params, effects, normals, albedo_dev, px_hits,
                                           pixels_dev, stamp)
        state = RenderState(
            params, shape, vertices, normals, albedo_dev, HostAlbedo(albedo_dev, albedo), hits,
            hits.prim_id, hits.bary, False, px_hits, geometry, px_albedo, None, effects,
            self._shading(params), (0, 0), pixels, pixels_dev, versions, stamp,
        )
        state = self._with_light(state, effects)
        for cache in (px_hits, geometry, px_albedo, state.pixel_light):
            cache.value  # the start of a chain: every step reuses them
        return state

    def update(self, state: RenderState, params: RenderParameter, touched: Block) -> RenderState:
        """Return the state for ``params``, recomputing only what ``touched`` makes stale.

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
        stamp = new_stamp()
        versions = bump(s.versions, touched)
        out = {}
        caster = self._slots.current
        if stale("geometry", touched):
            shape, n_shape = self._instances.update_shape(s.params, params, s.shape, n_shape)
            v32 = shape.reshape(-1, 3)
            vertices = jax.device_put(v32)
            out.update(shape=shape, vertices=vertices, geometry_pending=True,
                       normals=normals_stage(vertices, self._triangles))  # runs while Embree casts
            caster = self._slots.propose(v32)
        s = s._replace(params=params, versions=versions, stamp=stamp, **out)
        if stale("effects", touched):
            s = s._replace(effects=self.effects(params))
        if stale("shading", touched):
            s = s._replace(shading=self._shading(params))
        effects = s.effects
        albedo_changed = False
        if stale("albedo", touched):
            change = self._device_albedo.update(state, params)
            if change is not None:
                albedo_dev, host_albedo, n_albedo = change
                s = s._replace(albedo_dev=albedo_dev, host_albedo=host_albedo)
                albedo_changed = True
        s = s._replace(updates=(n_shape, n_albedo))
        # the pixel geometry is rebuilt without a ray cast when the effect set needs an
        # attribute the cached one lacks (view directions, specular albedo)
        rebuilt = False
        if stale("raycast", touched):
            hits = self._cast(params, caster, versions)
            pixels, pixels_dev, px_hits = self._hits_cache(hits, effects,
                                                           params.image_size.height, stamp)
            geometry, px_albedo = self._pixels(params, effects, s.normals, s.albedo_dev, px_hits,
                                               pixels_dev, stamp)
            s = s._replace(hits=hits, prim_id=hits.prim_id, bary=hits.bary, pixel_hits=px_hits,
                           pixel_geometry=geometry, pixel_albedo=px_albedo, pixels=pixels,
                           pixels_dev=pixels_dev)
        elif not pixels_satisfy(s.pixel_geometry, s.pixel_albedo, effects):
            geometry, px_albedo = self._pixels(params, effects, s.normals, s.albedo_dev,
                                               s.pixel_hits, s.pixels_dev, stamp)
            s = s._replace(pixel_geometry=geometry, pixel_albedo=px_albedo)
            rebuilt = True
        elif albedo_changed:
            s = s._replace(pixel_albedo=Deferred(
                albedo_stage(effects), {"hits": s.pixel_hits, "albedo_dev": s.albedo_dev}, effects,
                stamp))
        if (stale("light", touched) or rebuilt
                or light_effects(effects) != light_effects(state.effects)):
            s = self._with_light(s, effects)
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

    def _with_light(self, state: RenderState, effects: Effects) -> RenderState:
        """``state`` with its light transport (cast shadows reused while their key holds)."""
        shadow = self._shadow_cache(state, effects)
        return state._replace(shadow=shadow, pixel_light=self._light(state, effects, shadow))

    def _light(self, state: RenderState, effects: Effects, shadow=None) -> Deferred:
        """Deferred light transport of ``state`` (its pixel geometry must satisfy ``effects``)."""
        if effects.shadows and shadow is None:
            shadow = self._shadow_cache(state, effects)
        return Deferred(light_stage(light_effects(effects)),
                        {"geometry": state.pixel_geometry, "packed": state.shading,
                         "shadow": None if shadow is None else shadow[1]}, effects, state.stamp)

    def _shadow_cache(self, state: RenderState, effects: Effects):
        caster = self._slots.candidate if state.geometry_pending else self._slots.current
        return state_shadow(state, effects, caster, self.model.triangles, self.ray_counts,
                            rays=self.shadow_rays, spread_deg=self.shadow_spread_deg)

    def _shading_inputs(self, state: RenderState, effects: Effects | None):
        eff = state.effects if effects is None else effects
        if eff == state.effects:
            light, albedo = state.pixel_light, state.pixel_albedo
        else:  # another effect set than the cached one: compute what it needs
            if not pixels_satisfy(state.pixel_geometry, state.pixel_albedo, eff):
                geometry, albedo = self._pixels(state.params, eff, state.normals,
                                                state.albedo_dev, state.pixel_hits,
                                                state.pixels_dev, state.stamp)
                state = state._replace(pixel_geometry=geometry, pixel_albedo=albedo)
            light, albedo = self._light(state, eff), state.pixel_albedo
        return eff, (light.value, albedo.value, state.pixel_hits.mask, state.shading,
                     state.pixels_dev)

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
        """Return ``g(state, *args)``: this renderer's shading fused with ``fn`` in one ``jit``.

        See :func:`albedo_model.render.pixel_work.compose` (``fn(rgb, mask, *args)`` of
        the whole image, or ``fn(rgb, mask, pixels, *args)`` of the state's pixel set
        with ``pixel_set``).
        """
        return compose(fn, pixel_set=pixel_set)

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
        """Return the image's pixel coordinates (device, cached per size) and the packed camera."""
        w, h = int(p.image_size.width), int(p.image_size.height)
        if self._views_cache.get("size") != (w, h):
            self._views_cache = {"size": (w, h), "coords": jax.device_put(pixel_coordinates(w, h))}
        return self._views_cache["coords"], packed_camera(p)


def render(model: MorphableModel, params: RenderParameter, *, specular: bool = True,
           gamma: bool = False, shadows: bool = False, background=(0.0, 0.0, 0.0),
           shadow_rays: int = 1) -> Rendered:
    """Render one image of ``model`` with scene ``params`` (coefficients from ``params.momo``).

    Returns a :class:`Rendered`: ``image`` (H, W, 3) float32, ``mask`` (H, W) bool, the buffers.
    """
    renderer = Renderer(model, specular=specular, gamma=gamma, shadows=shadows,
                        background=background, shadow_rays=shadow_rays)
    return renderer.render(params)
