"""Differentiable re-rendering of ray-cast pixels: colours as a JAX function of the geometry.

A ray cast decides *which* triangle each pixel sees; with that held fixed (the
pixels and their ``prim_id``), a face pixel's colour is a smooth function of the
continuous geometry (:class:`GeometryParams`: shape and expression
coefficients, pose angles and translation, focal length). :func:`pixel_colours`
evaluates it in JAX: (1) the instance ``mean + U_s a + U_e b`` and its vertex
normals (the renderer's :func:`~albedo_model.render.normals.vertex_normal_columns`);
(2) each pixel's camera ray re-intersected with its triangle in the eye frame
(``p_e = s R_view R_pose p + t``; Möller-Trumbore, the barycentrics ``(u, v)``
Embree reports); (3) normals (rotated by the pose) and albedo (at the scene's
fixed albedo coefficients) interpolated with them; (4) the renderer's image
formation (:func:`~albedo_model.shading.image_formation.pixel_light`,
:func:`~albedo_model.shading.image_formation.combine_pixels`) with its view
directions (the reversed pixel rays).

Visibility is not differentiated (a pixel keeps its triangle, its plane
extrapolated beyond it, and its cast shadow); at the cast's parameters the
colours equal the renderer's image. Principal point, pose scaling, view, near
plane and image size are constants (:mod:`albedo_model.render.jacobian`
differentiates in them too). The dtype is the inputs'.

This module imports :mod:`albedo_model` (camera, errors, model, params),
:mod:`albedo_model.render` (instances, normals, pixel_work) and
:mod:`albedo_model.shading` (effects, image_formation, interpolation).
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from albedo_model.camera import eye_from_world, principal_point_px
from albedo_model.errors import InputError
from albedo_model.model import MorphableModel
from albedo_model.params import RenderParameter
from albedo_model.render.instances import ModelInstances
from albedo_model.render.normals import vertex_normal_columns
from albedo_model.render.pixel_work import choose_pixel_set
from albedo_model.shading.effects import Effects, effects_for
from albedo_model.shading.image_formation import (combine_pixels, pack_shading_params,
                                                  pixel_light, unpack_shading_params)
from albedo_model.shading.interpolation import (PixelAlbedo, PixelGeometry,
                                                needs_specular_albedo, needs_view, normalise)

__all__ = ["DifferentiableModel", "FixedHits", "GeometryParams", "PixelAttributes", "SceneInputs",
           "barycentric_weights", "build_value_and_grad", "euler_rotation_jax", "fixed_hits",
           "geometry_params", "instance_and_normals", "pixel_attributes", "pixel_colours",
           "shade_attributes"]


class GeometryParams(NamedTuple):
    """The geometry :func:`pixel_colours` is differentiated in (a pytree).

    Shape, expression (ks,), (ke,); yaw, pitch, roll (rad); translation (mm); focal length.
    """

    shape: jax.Array
    expression: jax.Array
    angles: jax.Array
    translation: jax.Array
    focal_length: jax.Array


class FixedHits(NamedTuple):
    """The pixels of a ray cast with their (fixed) triangles, padded to a bucketed size.

    Attributes
    ----------
    pixels : (C,) int32 host row-major indices (every face pixel, then padding misses)
    xs, ys : (C,) float32 pixel coordinates (x right, y down; pixel (i, j) is the point (i, j))
    prim_id : (C,) int32 hit triangle of each pixel (0 where ``mask`` is False)
    mask : (C,) bool, True on face pixels
    shadow : (C,) float32 or None, the directional light's visibility (held, as the triangles)
    """

    pixels: np.ndarray
    xs: jax.Array
    ys: jax.Array
    prim_id: jax.Array
    mask: jax.Array
    shadow: jax.Array | None = None


class SceneInputs(NamedTuple):
    """Everything :func:`pixel_colours` reads besides the geometry and the hits (a pytree).

    Attributes
    ----------
    mean : (n, 3) shape + expression mean, model frame (mm)
    shape_basis_t, expression_basis_t : (ks, 3n), (ke, 3n) scaled bases, transposed: XLA-CPU
        pulls ``c @ basis_t`` back contiguously (``basis @ c``: 4-7x its forward time).
    triangles : (m, 3) int32
    albedo : (n, 6) per-vertex diffuse and specular albedo (the scene's coefficients)
    packed : (PACKED_SIZE,) packed shading scalars (light, colour transform, background)
    camera : (8,) sensor width and height, image width and height, principal point
        (pixels), near-plane distance, pose scaling
    view : (3, 4) world-to-eye rotation and translation of the view
    """

    mean: jax.Array
    shape_basis_t: jax.Array
    expression_basis_t: jax.Array
    triangles: jax.Array
    albedo: jax.Array
    packed: jax.Array
    camera: jax.Array
    view: jax.Array


def geometry_params(params: RenderParameter, dtype=np.float32) -> GeometryParams:
    """Return the :class:`GeometryParams` of a scene as host arrays of ``dtype``."""
    p = params
    return GeometryParams(*(np.asarray(a, dtype) for a in (
        np.ravel(p.momo.shape), np.ravel(p.momo.expression),
        (p.pose.yaw, p.pose.pitch, p.pose.roll), p.pose.translation, p.camera.focal_length)))


def fixed_hits(prim_id: np.ndarray, width: int, height: int,
               capacity: int | None = None) -> tuple[FixedHits, int]:
    """Return the face pixels of a ray cast as :class:`FixedHits`, and the capacity to pass next.

    ``prim_id`` (H W,) int32: a ray cast's triangle per pixel (-1: miss, row-major).
    ``capacity`` is the previous call's for this image size (bucketed pixel-set
    sizes, :func:`~albedo_model.render.pixel_work.choose_pixel_set`: few compiled shapes).
    """
    prim_id = np.asarray(prim_id, np.int32).reshape(-1)
    pixels, capacity = choose_pixel_set(prim_id, int(height), capacity)
    if pixels is None:
        pixels = np.arange(prim_id.shape[0], dtype=np.int32)
    prim = prim_id[pixels]
    ys, xs = np.divmod(pixels, int(width))
    hits = FixedHits(pixels, jnp.asarray(xs, jnp.float32), jnp.asarray(ys, jnp.float32),
                     jnp.asarray(np.maximum(prim, 0), jnp.int32), jnp.asarray(prim >= 0))
    return hits, capacity


def euler_rotation_jax(roll, yaw, pitch) -> jax.Array:
    """Return ``Rz(roll) Ry(yaw) Rx(pitch)`` (as :func:`~albedo_model.camera.euler_rotation`)."""
    (cr, sr), (cy, sy), (cp, sp) = ((jnp.cos(a), jnp.sin(a)) for a in (roll, yaw, pitch))
    one, zero = jnp.ones_like(cr), jnp.zeros_like(cr)

    def m(*rows):
        return jnp.stack([jnp.stack(r) for r in rows])

    rz = m((cr, -sr, zero), (sr, cr, zero), (zero, zero, one))
    ry = m((cy, zero, sy), (zero, one, zero), (-sy, zero, cy))
    return rz @ ry @ m((one, zero, zero), (zero, cp, -sp), (zero, sp, cp))


def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _pixel_rays(geometry: GeometryParams, scene: SceneInputs, hits: FixedHits,
                orthographic: bool):
    """Eye-frame ray origins and directions of the pixels, as triples of (C,) arrays."""
    sx, sy, w, h, cx, cy = (scene.camera[i] for i in range(6))
    fx, fy = w * geometry.focal_length / sx, h * geometry.focal_length / sy
    a = (hits.xs.astype(fx.dtype) - cx) / fx
    b = -(hits.ys.astype(fx.dtype) - cy) / fy
    n = scene.camera[6]
    minus = -jnp.ones_like(a)
    if orthographic:
        return (n * a, n * b, n * minus), (jnp.zeros_like(a), jnp.zeros_like(a), minus)
    return (n * a, n * b, n * minus), (a, b, minus)


def barycentric_weights(geometry: GeometryParams, scene: SceneInputs, hits: FixedHits, corners,
                  orthographic: bool):
    """Weights ``(1-u-v, u, v)`` of each pixel's ray on its triangle of corners (C, 3) x 3."""
    v0, v1, v2 = corners
    yaw, pitch, roll = geometry.angles[0], geometry.angles[1], geometry.angles[2]
    view_r = scene.view[:, :3]
    rot = view_r @ euler_rotation_jax(roll, yaw, pitch) * scene.camera[7]
    trans = view_r @ geometry.translation + scene.view[:, 3]

    def eye(p, offset):  # (C, 3) model-frame points (or edges) -> eye-frame triple
        return tuple(p[:, 0] * rot[i, 0] + p[:, 1] * rot[i, 1] + p[:, 2] * rot[i, 2]
                     + offset[i] for i in range(3))

    zero = jnp.zeros(3, rot.dtype)  # edges: rotated model-frame differences (float32 accuracy)
    a = eye(v0, trans)
    e1, e2 = eye(v1 - v0, zero), eye(v2 - v0, zero)
    origin, direction = _pixel_rays(geometry, scene, hits, orthographic)
    p = _cross(direction, e2)
    det = _dot(e1, p)
    det = jnp.where(hits.mask & (jnp.abs(det) > 1e-30), det, 1.0)
    t = tuple(o - ac for o, ac in zip(origin, a))
    u = _dot(t, p) / det
    v = _dot(direction, _cross(t, e1)) / det
    u, v = jnp.where(hits.mask, u, 0.0), jnp.where(hits.mask, v, 0.0)
    return 1.0 - u - v, u, v


def _interp(rows, weight, start: int) -> tuple:
    """Columns ``start:start+3`` of the corner rows (C, k) x 3, interpolated with ``weight``."""
    return tuple(sum(w * r[:, start + k] for w, r in zip(weight, rows)) for k in range(3))


def _views(geometry: GeometryParams, scene: SceneInputs, hits: FixedHits, orthographic: bool):
    """Return unit directions towards the eye (world frame): the reversed pixel rays."""
    _, (dx, dy, dz) = _pixel_rays(geometry, scene, hits, orthographic)
    r = scene.view[:, :3]  # world = R^T eye
    world = [dx * r[0, c] + dy * r[1, c] + dz * r[2, c] for c in range(3)]
    return normalise(-world[0], -world[1], -world[2])


def instance_and_normals(shape, expression, scene: SceneInputs) -> tuple[jax.Array, tuple]:
    """Return the instance's vertices (n, 3) (model frame) and unit vertex normals (three (n,))."""
    flat = shape @ scene.shape_basis_t + expression @ scene.expression_basis_t
    vertices = scene.mean + flat.reshape(-1, 3)
    return vertices, vertex_normal_columns(vertices, scene.triangles)


class PixelAttributes(NamedTuple):
    """What the shading reads of each pixel: three (C,) arrays (``view``, ``specular`` or None)."""

    normal: tuple
    view: tuple | None
    diffuse: tuple
    specular: tuple | None


def pixel_attributes(effects: Effects, orthographic: bool, vertices, normals, angles,
                     translation, focal_length, scene: SceneInputs,
                     hits: FixedHits) -> PixelAttributes:
    """Re-intersect the rays with their triangles of ``vertices``, interpolate normals, albedo."""
    geometry = GeometryParams(None, None, angles, translation, focal_length)
    # one (n, 6) gather per corner: the reverse pass compiles ~2x faster than 18 column gathers
    corner = tuple(scene.triangles[:, j][hits.prim_id] for j in range(3))
    table = jnp.concatenate([vertices, jnp.stack(normals, axis=1)], axis=1)
    rows = tuple(table[c] for c in corner)
    weight = barycentric_weights(geometry, scene, hits, tuple(r[:, :3] for r in rows), orthographic)
    nm = _interp(rows, weight, 3)
    r = euler_rotation_jax(angles[2], angles[0], angles[1])
    normal = normalise(*(r[i, 0] * nm[0] + r[i, 1] * nm[1] + r[i, 2] * nm[2] for i in range(3)))
    view = _views(geometry, scene, hits, orthographic) if needs_view(effects) else None
    albedo = tuple(scene.albedo[c] for c in corner)  # (C, 6): diffuse, specular
    diffuse = _interp(albedo, weight, 0)
    specular = _interp(albedo, weight, 3) if needs_specular_albedo(effects) else None
    return PixelAttributes(normal, view, diffuse, specular)


def shade_attributes(effects: Effects, attributes: PixelAttributes, scene: SceneInputs,
                     hits: FixedHits) -> tuple[tuple, jax.Array]:
    """Shade per-pixel attributes with the renderer's image formation: ``(rgb, mask)``."""
    if effects.shadows and hits.shadow is None:
        raise InputError("cast shadows need the pixels' light visibility (FixedHits.shadow)")
    a = attributes
    params = unpack_shading_params(scene.packed)
    light = pixel_light(effects, PixelGeometry(hits.mask, a.normal, a.view), params,
                        hits.shadow if effects.shadows else None)
    out = combine_pixels(effects, light, PixelAlbedo(a.diffuse, a.specular), hits.mask, params)
    return out.rgb, out.mask


def pixel_colours(effects: Effects, orthographic: bool, geometry: GeometryParams,
                  scene: SceneInputs, hits: FixedHits) -> tuple[tuple, jax.Array]:
    """Return the linear colours of the fixed-hit pixels at ``geometry`` (pure JAX).

    ``effects`` (the renderer's effect set, no shadows) and ``orthographic`` are
    static; ``scene`` is from :meth:`DifferentiableModel.scene`, ``hits`` from
    :func:`fixed_hits` (the ray cast whose visibility is held). Returns three
    (C,) colour arrays (clamped as the effects say; the background where ``mask``
    is False) and the (C,) bool ``mask``.
    """
    g = geometry
    vertices, normals = instance_and_normals(g.shape, g.expression, scene)
    return shade_attributes(effects, pixel_attributes(
        effects, orthographic, vertices, normals, g.angles, g.translation, g.focal_length, scene,
        hits), scene, hits)


@functools.cache
def _stages(effects: Effects, orthographic: bool) -> tuple:
    """Return the jitted programs of :func:`build_value_and_grad` that ignore the read-out."""
    attributes = functools.partial(pixel_attributes, effects, orthographic)

    @jax.jit
    def attrs_backward(vertices, normals, angles, translation, focal, scene, hits, cotangent):
        _, pullback = jax.vjp(lambda *x: attributes(*x, scene, hits), vertices, normals, angles,
                              translation, focal)
        return pullback(cotangent)

    @jax.jit
    def instance_backward(shape, expression, scene, cotangent):
        _, pullback = jax.vjp(lambda a, b: instance_and_normals(a, b, scene), shape, expression)
        return pullback(cotangent)

    return jax.jit(instance_and_normals), jax.jit(attributes), attrs_backward, instance_backward


@functools.cache
def build_value_and_grad(effects: Effects, orthographic: bool, readout):
    """Return ``f(geometry, scene, hits, *args) -> ((value, aux), grad)`` of a colour read-out.

    ``readout(rgb, mask, *args) -> (value, aux)`` is a pure JAX function of
    :func:`pixel_colours`' output (e.g. a likelihood); ``grad`` is the
    :class:`GeometryParams` gradient of ``value``.

    Notes
    -----
    Four jitted programs chained by hand (instance and normals; pixel attributes; shading
    + read-out with its gradient; the two vector-Jacobian products): one fused program
    gives the same numbers but takes XLA-CPU 15-30 s to compile, the four a few seconds.
    """
    forward, attrs_forward, attrs_backward, instance_backward = _stages(effects, orthographic)

    def shaded(attrs, scene, hits, *args):
        return readout(*shade_attributes(effects, attrs, scene, hits), *args)

    shading = jax.jit(jax.value_and_grad(shaded, has_aux=True))

    def value_and_grad(geometry: GeometryParams, scene: SceneInputs, hits: FixedHits, *args):
        hits, g = hits._replace(pixels=None), geometry
        vertices, normals = forward(g.shape, g.expression, scene)
        pose = (g.angles, g.translation, g.focal_length)
        out, g_attrs = shading(attrs_forward(vertices, normals, *pose, scene, hits), scene, hits,
                               *args)
        g_v, g_n, g_a, g_t, g_f = attrs_backward(vertices, normals, *pose, scene, hits, g_attrs)
        g_s, g_e = instance_backward(g.shape, g.expression, scene, (g_v, g_n))
        return out, GeometryParams(g_s, g_e, g_a, g_t, g_f)

    return value_and_grad


class DifferentiableModel:
    """The per-model inputs of :func:`pixel_colours`, with the renderer's shading settings.

    Parameters
    ----------
    model : MorphableModel
    specular, background, directional_specular_map
        As the :class:`~albedo_model.render.renderer.Renderer`'s (linear output).
    """

    def __init__(self, model: MorphableModel, *, specular: bool = True,
                 background=(0.0, 0.0, 0.0), directional_specular_map: bool = False):
        self.model = model
        self.specular = bool(specular and model.specular is not None)
        self.background = tuple(float(b) for b in background)
        self.directional_specular_map = bool(directional_specular_map)
        self._instances = ModelInstances(model, self.specular)
        self._device: dict = {}
        self._albedo: tuple | None = None

    def effects(self, params: RenderParameter) -> Effects:
        """Return the effect set of ``params`` (the renderer's, linear output, no shadows)."""
        return effects_for(params, self.specular,
                           directional_specular_map=self.directional_specular_map)

    def _bases(self, ks: int, ke: int, dtype) -> tuple:
        """Device mean (n, 3) and transposed scaled bases truncated to ``ks`` / ``ke`` (cached)."""
        key = (ks, ke, np.dtype(dtype).name)
        if key not in self._device:
            m = self.model
            mean, eb = m.shape.mean.astype(np.float64), np.zeros((m.shape.dim, ke))
            if m.expression is not None:
                mean = mean + m.expression.mean
                eb = m.expression.scaled_basis[:, :ke]
            if ks > m.shape.rank or eb.shape[1] != ke:
                raise InputError(f"{ks} shape / {ke} expression coefficients exceed the model's")
            dev = functools.partial(jnp.asarray, dtype=dtype)  # .T.copy(): row-major (k, 3n)
            sb = m.shape.scaled_basis[:, :ks]
            self._device[key] = (dev(mean.reshape(-1, 3)), dev(sb.T.copy()), dev(eb.T.copy()),
                                 jnp.asarray(m.triangles, jnp.int32))
        return self._device[key]

    def scene(self, params: RenderParameter, dtype=np.float32, *,
              albedo: bool = True) -> SceneInputs:
        """Return the :class:`SceneInputs` of ``params`` (computed in ``dtype``).

        ``albedo=False``: a zero placeholder albedo (for callers that form it).
        """
        p = params
        mean, sb, eb, tri = self._bases(len(p.momo.shape), len(p.momo.expression), dtype)
        c, dt = np.asarray(p.momo.albedo, np.float64), np.dtype(dtype).name
        last = self._albedo  # the last albedo, kept while its coefficients are equal
        if not albedo:
            last = (None, dt, jnp.zeros((mean.shape[0], 6), dtype))
        elif last is None or last[1] != dt or not np.array_equal(last[0], c):
            albedo = self._instances.albedo(p).astype(np.float64).reshape(-1, mean.shape[0], 3)
            albedo = np.concatenate([albedo, np.zeros_like(albedo)])[:2]
            self._albedo = last = (c.copy(), dt, jnp.asarray(np.concatenate(albedo, 1), dtype))
        packed = pack_shading_params(p, np.eye(3), background=self.background)
        cam = [*p.camera.sensor_size, p.image_size.width, p.image_size.height,
               *principal_point_px(p.camera, p.image_size), p.camera.near, p.pose.scaling]
        rv, tv = eye_from_world(p.view)
        arr = functools.partial(jnp.asarray, dtype=dtype)
        return SceneInputs(mean, sb, eb, tri, last[2], arr(packed), arr(cam),
                           arr(np.concatenate([rv, tv[:, None]], axis=1)))
