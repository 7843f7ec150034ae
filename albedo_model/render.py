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
LIGHT, COLOR, SPEC. EXP.     nothing before shading
==========================  =================================================

Shading then runs over the cached pixel attributes only
(:func:`albedo_model.shading.shade_pixels`, compiled for the scene's effect set),
so a light step is a single pass over the pixels. :meth:`Renderer.compose` fuses
that pass with a caller's function (a likelihood) in one ``jit``. A geometry
change is cast with the spare scene; the sampler calls :meth:`Renderer.accept`
or :meth:`Renderer.reject`, so a rejected proposal costs nothing to undo.

This module imports only ``albedo_model`` modules.
"""

from __future__ import annotations

from collections.abc import Callable

import jax.numpy as jnp
import numpy as np

from albedo_model.camera import (
    _eye_rays, camera_rays, euler_rotation, eye_from_world, eye_position_model, project,
    towards_camera_model,
)
from albedo_model.errors import InputError
from albedo_model.instance_updates import InstanceUpdater, coefficients_for
from albedo_model.interpolation import needs_view
from albedo_model.model import MorphableModel
from albedo_model.params import Block, RenderParameter
from albedo_model.raycast import RayHits, visible_points
from albedo_model.render_state import (
    Rendered, RenderState, albedo_stage, fused_stage, normals_stage, pixels_satisfy,
    pixels_stage, shade_stage,
)
from albedo_model.scene_slots import SceneSlots
from albedo_model.shading import Effects, Shaded, effects_for, pack_shading_params, to_hwc
from albedo_model.shadows import directional_visibility

__all__ = ["Renderer", "RenderState", "Rendered", "STAGE_DEPS", "render"]

#: Which touched blocks make each cached stage stale.
STAGE_DEPS = {
    "geometry": Block.SHAPE | Block.EXPRESSION,
    "raycast": Block.SHAPE | Block.EXPRESSION | Block.POSE | Block.CAMERA,
    "albedo": Block.ALBEDO,
    "shading": Block.POSE | Block.LIGHT | Block.COLOR | Block.SPECULAR_EXPONENT,
}


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
        self._ray_buffers: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}
        self._dirs_cache: dict = {}
        self._updater = InstanceUpdater()

    # -- effects ------------------------------------------------------------
    def effects(self, params: RenderParameter) -> Effects:
        """The effect set this renderer compiles for ``params``."""
        return effects_for(params, self.specular, shadows=self.shadows, gamma=self.gamma,
                           directional_specular_map=self.directional_specular_map)

    # -- stages ---------------------------------------------------------------
    def _shape_terms(self, params: RenderParameter) -> list:
        m = self.model
        terms = [((m.shape,), coefficients_for(m.shape, params.momo.shape, "shape"))]
        expr = coefficients_for(m.expression, params.momo.expression, "expression")
        if m.expression is not None:
            terms.append(((m.expression,), expr))
        return terms

    def _albedo_instance(self, params: RenderParameter) -> np.ndarray:
        """(1, 3n) diffuse or (2, 3n) diffuse + specular float32 host instance."""
        m = self.model
        c = coefficients_for(m.diffuse, params.momo.color, "colour")
        if not self.specular:
            return self._updater.instance([((m.diffuse,), c)]).reshape(1, -1)
        if m.shared_albedo:
            return self._updater.instance([((m.diffuse, m.specular), c)]).reshape(2, -1)
        # independent specular albedo has no coefficients in a scene: its mean
        return np.stack([self._updater.instance([((m.diffuse,), c)]),
                         m.specular.mean.astype(np.float32)])

    def _albedo_update(self, state: RenderState, params: RenderParameter):
        """(albedo, count): ``state.albedo`` itself when no coefficient changed."""
        m = self.model
        old = coefficients_for(m.diffuse, state.params.momo.color, "colour")
        new = coefficients_for(m.diffuse, params.momo.color, "colour")
        shared = self.specular and m.shared_albedo
        parts = (m.diffuse, m.specular) if shared else (m.diffuse,)
        base = state.albedo.reshape(-1) if shared else state.albedo[0]
        flat, count = self._updater.update([(parts, old, new)], base, state.updates[1])
        if flat is base:
            return state.albedo, count
        if shared or len(state.albedo) == 1:
            return flat.reshape(len(state.albedo), -1), count
        return np.stack([flat, state.albedo[1]]), count

    def _cast(self, params: RenderParameter, caster) -> RayHits:
        size = params.image_size
        key = (int(size.width), int(size.height))
        if key not in self._ray_buffers:
            p = key[0] * key[1]
            self._ray_buffers = {key: (np.empty((p, 3), np.float32), np.empty((p, 3), np.float32))}
        origins, directions = camera_rays(params.camera, size, params.pose, params.view,
                                          out=self._ray_buffers[key])
        tfar = float(params.camera.far - params.camera.near)
        return caster.cast(origins, directions, tfar=tfar, image_shape=(key[1], key[0]))

    def _pixels(self, params: RenderParameter, effects: Effects, normals, albedo_dev, hits):
        p = params
        rotation = euler_rotation(p.pose.roll, p.pose.yaw, p.pose.pitch).astype(np.float32)
        ray_dirs = self._world_ray_dirs(p) if needs_view(effects) else None
        return pixels_stage(effects)(self._triangles, normals, albedo_dev, hits.prim_id,
                                     hits.bary, ray_dirs, rotation)

    def _shading(self, params: RenderParameter) -> np.ndarray:
        p = params
        rotation = euler_rotation(p.pose.roll, p.pose.yaw, p.pose.pitch)
        return pack_shading_params(p, rotation, background=self.background)

    # -- public API -------------------------------------------------------------
    def init_state(self, params: RenderParameter) -> RenderState:
        """Compute every stage for ``params`` and make its geometry the accepted one."""
        shape = self._updater.instance(self._shape_terms(params))
        v32 = shape.reshape(-1, 3)
        vertices = jnp.asarray(v32)
        normals = normals_stage(vertices, self._triangles)
        if self._slots is None:
            kw = {} if self._threads is None else {"threads": self._threads}
            self._slots = SceneSlots(v32, self.model.triangles, **kw)
        else:
            self._slots.reject()
            self._slots.current.update_vertices(v32)
        hits = self._cast(params, self._slots.current)
        albedo = self._albedo_instance(params)
        albedo_dev = jnp.asarray(albedo)
        effects = self.effects(params)
        px_hits, geometry, px_albedo = self._pixels(params, effects, normals, albedo_dev, hits)
        return RenderState(
            params, shape, albedo, albedo[0], albedo[1] if self.specular else None, vertices,
            normals, albedo_dev, hits, hits.prim_id, hits.bary, False, px_hits, geometry,
            px_albedo, effects, self._shading(params),
        )

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
            old, new = self._shape_terms(s.params), self._shape_terms(params)
            terms = [(parts, a, b) for (parts, a), (_, b) in zip(old, new)]
            shape, n_shape = self._updater.update(terms, s.shape, n_shape)
            v32 = shape.reshape(-1, 3)
            vertices = jnp.asarray(v32)
            out.update(shape=shape, vertices=vertices, geometry_pending=True,
                       normals=normals_stage(vertices, self._triangles))  # runs while Embree casts
            caster = self._slots.propose(v32)
        if touched & STAGE_DEPS["albedo"]:
            albedo, n_albedo = self._albedo_update(s, params)
            if albedo is not s.albedo:
                out.update(albedo=albedo, diffuse=albedo[0], albedo_dev=jnp.asarray(albedo),
                           specular=albedo[1] if len(albedo) > 1 else None)
        s = s._replace(params=params, updates=(n_shape, n_albedo), **out)
        if touched & (Block.LIGHT | Block.COLOR):
            s = s._replace(effects=self.effects(params))
        if touched & STAGE_DEPS["shading"]:
            s = s._replace(shading=self._shading(params))
        effects = s.effects
        if touched & STAGE_DEPS["raycast"]:
            hits = self._cast(params, caster)
            px_hits, geometry, px_albedo = self._pixels(params, effects, s.normals, s.albedo_dev,
                                                        hits)
            s = s._replace(hits=hits, prim_id=hits.prim_id, bary=hits.bary, pixel_hits=px_hits,
                           pixel_geometry=geometry, pixel_albedo=px_albedo)
        elif not pixels_satisfy(s.pixel_geometry, s.pixel_albedo, effects):
            px_hits, geometry, px_albedo = self._pixels(params, effects, s.normals, s.albedo_dev,
                                                        s.hits)
            s = s._replace(pixel_geometry=geometry, pixel_albedo=px_albedo)
        elif "albedo_dev" in out:
            s = s._replace(pixel_albedo=albedo_stage(effects)(s.pixel_hits, s.albedo_dev))
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

    def _shading_inputs(self, state: RenderState, effects: Effects | None):
        eff = state.effects if effects is None else effects
        geometry, albedo = state.pixel_geometry, state.pixel_albedo
        if not pixels_satisfy(geometry, albedo, eff):
            _, geometry, albedo = self._pixels(state.params, eff, state.normals,
                                               state.albedo_dev, state.hits)
        shadow = self._shadow(state) if eff.shadows else None
        return eff, (geometry, albedo, state.shading, shadow)

    def shade(self, state: RenderState, *, effects: Effects | None = None) -> Shaded:
        """Shade the state's cached pixels (device arrays; see :func:`albedo_model.shading.shade`).

        Parameters
        ----------
        state : RenderState
        effects : Effects, optional
            Override the renderer's effect set (e.g. to compare effect costs).
        """
        eff, inputs = self._shading_inputs(state, effects)
        return shade_stage(eff)(*inputs)

    def compose(self, fn: Callable) -> Callable:
        """Shading fused with ``fn`` in one ``jit``: ``g(state, *args) -> fn(rgb, mask, *args)``.

        Parameters
        ----------
        fn : callable
            A pure JAX function ``fn(rgb, mask, *args)`` of the shader output
            (``rgb`` three (P,) float32 arrays, linear unless the renderer
            gamma-encodes; ``mask`` (P,) bool) and of further arguments (arrays
            or pytrees, e.g. a target image), typically a likelihood.

        Returns
        -------
        callable
            ``g(state, *args)``: shades ``state`` as :meth:`shade` does and applies
            ``fn`` inside the same compiled function, returning ``fn``'s (device)
            result. XLA fuses the per-pixel shading into ``fn``'s reductions, so
            no image is written out. One compile per effect set and argument
            structure: keep ``fn`` and the argument shapes fixed.

        Examples
        --------
        >>> def sq_error(rgb, mask, target):
        ...     sq = sum((rgb[c] - target[c]) ** 2 for c in range(3))
        ...     return jnp.sum(jnp.where(mask, sq, 0.0))
        >>> error = renderer.compose(sq_error)            # doctest: +SKIP
        >>> value = float(error(state, target))           # doctest: +SKIP
        """
        compiled: dict[Effects, Callable] = {}

        def composed(state: RenderState, *args):
            eff, inputs = self._shading_inputs(state, None)
            run = compiled.get(eff)
            if run is None:
                run = compiled[eff] = fused_stage(eff, fn)
            return run(*inputs, *args)

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
        lv = self.model.landmark_vertices
        names = list(lv) if names is None else [n for n in names if n in lv]
        if not names:
            return [], np.zeros((0, 2)), np.zeros(0, bool)
        idx = np.array([lv[n] for n in names])
        p = state.params
        pts = state.shape.reshape(-1, 3)[idx]
        pixels, depth = project(pts, p.pose, p.view, p.camera, p.image_size)
        caster = self._slots.candidate if state.geometry_pending else self._slots.current
        if p.camera.orthographic:
            vis = visible_points(pts, None, caster, direction=towards_camera_model(p.pose, p.view))
        else:
            vis = visible_points(pts, eye_position_model(p.pose, p.view), caster)
        w, h = p.image_size
        inside = ((pixels[:, 0] >= -0.5) & (pixels[:, 0] <= w - 0.5)
                  & (pixels[:, 1] >= -0.5) & (pixels[:, 1] <= h - 0.5) & (depth > 0) & (depth < 1))
        return names, pixels, vis & inside

    def _world_ray_dirs(self, p: RenderParameter):
        key = (p.camera, p.image_size, p.view)
        if key not in self._dirs_cache:
            _, dirs = _eye_rays(p.camera, p.image_size)
            r, _ = eye_from_world(p.view)
            # eye = R world + t, so a world direction is R^T applied to the eye direction
            world = np.ascontiguousarray(dirs[:, :3] @ r, np.float32)
            self._dirs_cache = {key: jnp.asarray(world)}
        return self._dirs_cache[key]

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
