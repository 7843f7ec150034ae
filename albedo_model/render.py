"""Rendering a model instance: cached stages driven by the blocks a change touches.

A :class:`Renderer` owns the host resources of one model (two Embree scenes for
double buffering, device copies of the triangles) and turns scene parameters
into a :class:`RenderState`: the per-vertex instance (positions, normals,
diffuse and specular albedo) and the ray-cast buffers of every pixel. The state
is immutable; :meth:`Renderer.update` returns a new one and recomputes only the
stages whose inputs a change touched (``STAGE_DEPS``):

==========================  =================================================
touched                      recomputed
==========================  =================================================
SHAPE, EXPRESSION            changed block of the instance, normals, BVH refit
                             (into the spare scene), ray cast
POSE, CAMERA                 rays (transformed into the model frame), ray cast
ALBEDO                       changed block of the albedo instance
LIGHT, COLOR, SPEC. EXP.     nothing before shading
==========================  =================================================

Shading (:mod:`albedo_model.shading`) always runs, compiled for the scene's
effect set. A geometry change is cast with the spare scene; the sampler calls
:meth:`Renderer.accept` or :meth:`Renderer.reject`, so a rejected proposal
costs nothing to undo.

This module imports only ``albedo_model`` modules.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from albedo_model.camera import (
    _eye_rays, camera_rays, euler_rotation, eye_from_world, eye_position_model, project,
    towards_camera_model,
)
from albedo_model.errors import InputError
from albedo_model.model import MorphableModel
from albedo_model.normals_jax import vertex_normals_jax
from albedo_model.params import Block, RenderParameter
from albedo_model.raycast import RayHits, visible_points
from albedo_model.scene_slots import SceneSlots
from albedo_model.shading import Effects, Shaded, effects_for, shade, shading_params, to_hwc

__all__ = ["Renderer", "RenderState", "Rendered", "STAGE_DEPS", "render"]

#: Which touched blocks make each cached stage stale.
STAGE_DEPS = {
    "geometry": Block.SHAPE | Block.EXPRESSION,
    "raycast": Block.SHAPE | Block.EXPRESSION | Block.POSE | Block.CAMERA,
    "albedo": Block.ALBEDO,
}


class RenderState(NamedTuple):
    """Everything cached for one set of scene parameters (host and device arrays).

    Attributes
    ----------
    params : RenderParameter
    shape : (3n,) float64, host
        Shape + expression instance, interleaved (model frame, mm).
    diffuse, specular : (3n,) float64 host arrays (specular None without a part)
    vertices, normals : (n, 3) float32 device arrays, model frame
    diffuse_dev, specular_dev : (n, 3) float32 device arrays
    hits : RayHits
        Host ray-cast buffers of every pixel (row-major).
    prim_id : (P,) int32 device, bary : (P, 2) float32 device
    geometry_pending : bool
        True when the state's geometry lives in the renderer's spare scene
        (a proposal not yet accepted).
    """

    params: RenderParameter
    shape: np.ndarray
    diffuse: np.ndarray
    specular: np.ndarray | None
    vertices: object
    normals: object
    diffuse_dev: object
    specular_dev: object
    hits: RayHits
    prim_id: object
    bary: object
    geometry_pending: bool = False


class Rendered(NamedTuple):
    """A rendered image.

    Attributes
    ----------
    image : (H, W, 3) float32, linear or gamma-encoded as requested
    mask : (H, W) bool, True on the face (alpha 1)
    state : RenderState, the buffers behind the image
    """

    image: np.ndarray
    mask: np.ndarray
    state: RenderState


def _coefficients(part, c: np.ndarray, name: str, source: str = "parameters") -> np.ndarray:
    c = np.asarray(c, np.float64).reshape(-1)
    if part is None:
        if np.any(c != 0):
            raise InputError(f"{source} give {name} coefficients but the model has no {name} part")
        return c[:0]
    if c.shape[0] > part.rank:
        raise InputError(
            f"{source} give {c.shape[0]} {name} coefficients, the model's {name} part has rank {part.rank}"
        )
    return c


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

    # -- effects ------------------------------------------------------------
    def effects(self, params: RenderParameter) -> Effects:
        """The effect set this renderer compiles for ``params``."""
        return effects_for(params, self.specular, shadows=self.shadows, gamma=self.gamma,
                           directional_specular_map=self.directional_specular_map)

    # -- stages ---------------------------------------------------------------
    def _shape(self, params: RenderParameter) -> np.ndarray:
        m = self.model
        flat = m.shape.instance(_coefficients(m.shape, params.momo.shape, "shape"))
        expr = _coefficients(m.expression, params.momo.expression, "expression")
        if m.expression is not None:
            flat = flat + m.expression.instance(expr)
        return flat

    def _albedo(self, params: RenderParameter) -> tuple[np.ndarray, np.ndarray | None]:
        m = self.model
        c = _coefficients(m.diffuse, params.momo.color, "colour")
        diffuse = m.diffuse.instance(c)
        specular = None
        if self.specular:
            cs = c[: m.specular.rank] if m.shared_albedo else None
            specular = m.specular.instance(cs)
        return diffuse, specular

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

    def _geometry(self, shape: np.ndarray):
        v32 = np.ascontiguousarray(shape.reshape(-1, 3), np.float32)
        vertices = jnp.asarray(v32)
        return v32, vertices, vertex_normals_jax(vertices, self._triangles)

    # -- public API -------------------------------------------------------------
    def init_state(self, params: RenderParameter) -> RenderState:
        """Compute every stage for ``params`` and make its geometry the accepted one."""
        shape = self._shape(params)
        v32, vertices, normals = self._geometry(shape)
        if self._slots is None:
            kw = {} if self._threads is None else {"threads": self._threads}
            self._slots = SceneSlots(v32, self.model.triangles, **kw)
        else:
            self._slots.reject()
            self._slots.current.update_vertices(v32)
        hits = self._cast(params, self._slots.current)
        diffuse, specular = self._albedo(params)
        return RenderState(
            params, shape, diffuse, specular, vertices, normals,
            jnp.asarray(diffuse.reshape(-1, 3), jnp.float32),
            None if specular is None else jnp.asarray(specular.reshape(-1, 3), jnp.float32),
            hits, jnp.asarray(hits.prim_id), jnp.asarray(hits.bary),
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
        m = self.model
        shape, vertices, normals = state.shape, state.vertices, state.normals
        pending = False
        caster = self._slots.current
        if touched & STAGE_DEPS["geometry"]:
            old, new = state.params.momo, params.momo
            shape = m.shape.update_instance(
                shape, _coefficients(m.shape, old.shape, "shape"),
                _coefficients(m.shape, new.shape, "shape"),
            )
            if m.expression is not None:
                shape = m.expression.update_instance(
                    shape, _coefficients(m.expression, old.expression, "expression"),
                    _coefficients(m.expression, new.expression, "expression"),
                )
            v32, vertices, normals = self._geometry(shape)
            caster = self._slots.propose(v32)
            pending = True
        hits, prim_id, bary = state.hits, state.prim_id, state.bary
        if touched & STAGE_DEPS["raycast"]:
            hits = self._cast(params, caster)
            prim_id, bary = jnp.asarray(hits.prim_id), jnp.asarray(hits.bary)
        diffuse, specular = state.diffuse, state.specular
        diffuse_dev, specular_dev = state.diffuse_dev, state.specular_dev
        if touched & STAGE_DEPS["albedo"]:
            old = _coefficients(m.diffuse, state.params.momo.color, "colour")
            new = _coefficients(m.diffuse, params.momo.color, "colour")
            diffuse = m.diffuse.update_instance(diffuse, old, new)
            diffuse_dev = jnp.asarray(diffuse.reshape(-1, 3), jnp.float32)
            if specular is not None and m.shared_albedo:
                k = m.specular.rank
                specular = m.specular.update_instance(specular, old[:k], new[:k])
                specular_dev = jnp.asarray(specular.reshape(-1, 3), jnp.float32)
        return RenderState(params, shape, diffuse, specular, vertices, normals, diffuse_dev,
                           specular_dev, hits, prim_id, bary, pending)

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

    def shade(self, state: RenderState, *, effects: Effects | None = None) -> Shaded:
        """Shade the state's pixels (device arrays; see :func:`albedo_model.shading.shade`)."""
        p = state.params
        eff = self.effects(p) if effects is None else effects
        rotation = euler_rotation(p.pose.roll, p.pose.yaw, p.pose.pitch)
        sp = shading_params(p, rotation, background=self.background)
        ray_dirs = self._world_ray_dirs(p) if (eff.specular or eff.directional) else None
        shadow = self._shadow(state) if eff.shadows else None
        return shade(eff, self._triangles, state.normals, state.diffuse_dev,
                     state.specular_dev if (eff.specular or eff.directional_specular_map) else None,
                     state.prim_id, state.bary, ray_dirs, sp, shadow)

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

    def _shadow(self, state: RenderState):
        p = state.params
        hits = state.hits
        idx = np.flatnonzero(hits.prim_id >= 0)
        shadow = np.ones(len(hits.prim_id), np.float32)
        if idx.size == 0:
            return jnp.asarray(shadow)
        v = state.shape.reshape(-1, 3)
        tri = self.model.triangles[hits.prim_id[idx]]
        u, w = hits.bary[idx, :1], hits.bary[idx, 1:]
        pts = (1.0 - u - w) * v[tri[:, 0]] + u * v[tri[:, 1]] + w * v[tri[:, 2]]
        r = euler_rotation(p.pose.roll, p.pose.yaw, p.pose.pitch)
        l_world = np.asarray(p.directional_light.direction, np.float64)
        l_model = r.T @ (l_world / np.linalg.norm(l_world))
        caster = self._slots.candidate if state.geometry_pending else self._slots.current
        start = (pts + 1e-4 * caster.scale * l_model).astype(np.float32)
        occ = caster.occluded(start, l_model.reshape(1, 3).astype(np.float32))
        shadow[idx[occ]] = 0.0
        return jnp.asarray(shadow)


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
