"""The Jacobian of fixed-hit pixel colours in every continuous scene parameter (JAX, forward mode).

:mod:`albedo_model.render.differentiable` renders the pixels of a ray cast at
fixed triangles as a JAX function of the geometry. Here the same colours are a
function of one flat vector of **all** continuous scene parameters
(:class:`~albedo_model.scene_vector.SceneLayout`: shape and expression coefficients, pose angles and
translation, focal length, principal point, SH light, colour transform,
specular exponent, albedo coefficients), and :meth:`PixelJacobian.jacobian`
returns their Jacobian ``(3, C, D)`` as well. It is what a Gauss-Newton step
and a Laplace approximation of the posterior read
(:mod:`mcmcfit.targets.curvature`).

Forward mode, in three separately compiled stages: (1) the vertices and
vertex normals in the shape and expression coefficients; (2) the pixel
attributes (re-intersection, interpolated normals, albedo, view directions)
in the geometry, the camera and the albedo coefficients; (3) the shading in
the attributes, the light, the colour transform and the specular exponent.
One fused ``jacfwd`` of the whole chain gives the same numbers but XLA-CPU
fuses the gathers into their consumers and recomputes them per direction
(about 200 s for 137 directions at 250^2, against about 1 s here).

Visibility is held fixed (the hits' triangles and cast shadows), as in
:mod:`~albedo_model.render.differentiable`; the colour transform is always
applied (so that its entries have derivatives at the identity). A layout with
a directional light differentiates in its azimuth, elevation and strength too
(its specular colour is its diffuse colour, as the layout writes it).

This module imports :mod:`albedo_model.errors`, :mod:`albedo_model.model`,
:mod:`albedo_model.params`, :mod:`albedo_model.scene_vector`,
:mod:`albedo_model.render` (differentiable, normals) and :mod:`albedo_model.shading`
(effects, scalars).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from albedo_model.errors import InputError
from albedo_model.model import MorphableModel
from albedo_model.params import RenderParameter
from albedo_model.render.differentiable import (
    DifferentiableModel, FixedHits, GeometryParams, SceneInputs, barycentric_weights,
    pixel_attributes, shade_attributes,
)
from albedo_model.render.normals import vertex_normal_columns, vertex_normal_tangents
from albedo_model.scene_vector import SceneLayout
from albedo_model.shading.effects import Effects
from albedo_model.shading.scalars import packed_slice

__all__ = ["PixelJacobian", "SceneLayout"]


def _stages(layout: SceneLayout, effects: Effects, orthographic: bool):
    """Return the three jitted stages and their forward-mode derivatives (module notes)."""
    sl = layout.slices()
    ks, ke = layout.n_shape, layout.n_expression
    geo = np.r_[sl["shape"], sl["expression"]]
    n_geometry = np.r_[geo, sl["angles"], sl["translation"], sl["focal_length"],
                       sl["principal_point"]].size
    light = packed_slice("sh")

    def vertices(x, scene: SceneInputs):
        flat = x[sl["shape"]] @ scene.shape_basis_t + x[sl["expression"]] @ scene.expression_basis_t
        v = scene.mean + flat.reshape(-1, 3)
        return v, vertex_normal_columns(v, scene.triangles)

    def albedo_table(x, albedo_mean, albedo_basis_t):
        return albedo_mean + (x[sl["albedo"]] @ albedo_basis_t).reshape(albedo_mean.shape)

    def camera(x, scene: SceneInputs):
        w, h = scene.camera[2], scene.camera[3]
        pp = x[sl["principal_point"]]
        return scene.camera.at[4].set(0.5 * w * (1.0 + pp[0])).at[5].set(0.5 * h * (1.0 - pp[1]))

    def packed(x, scene: SceneInputs):
        out = scene.packed.at[light.start:light.start + 3 * layout.n_light].set(x[sl["light"]])
        for name, entry in (("specular_exponent", "specular_exponent"), ("color_gain", "gain"),
                            ("color_contrast", "contrast"), ("color_offset", "offset")):
            out = out.at[packed_slice(name)].set(x[sl[entry]])
        if layout.directional:
            az, el = x[sl["light_angles"]][0], x[sl["light_angles"]][1]
            direction = jnp.stack([jnp.sin(az) * jnp.cos(el), jnp.sin(el),
                                   jnp.cos(az) * jnp.cos(el)])
            out = out.at[packed_slice("light_direction")].set(direction)
            for name in ("light_diffuse", "light_specular"):
                out = out.at[packed_slice(name)].set(x[sl["light_intensity"]])
        return out

    def attributes(v, normals, table, x, scene, hits):
        sc = scene._replace(albedo=table, camera=camera(x, scene))
        return pixel_attributes(effects, orthographic, v, normals, x[sl["angles"]],
                                x[sl["translation"]], x[sl["focal_length"]][0], sc, hits)

    def shading(attrs, x, scene, hits):
        sc = scene._replace(packed=packed(x, scene))
        return jnp.stack(shade_attributes(effects, attrs, sc, hits)[0])

    def vertex_tangents(v, scene):
        """Vertex and normal tangents (n, 3, G), three (n, G) along the G geometry directions.

        ``v`` are the vertices at the point. They are linear in the coefficients
        (their tangents are the bases' columns); the pose and camera directions
        move no vertex (zeros).
        """
        n = scene.mean.shape[0]
        dv = jnp.concatenate([scene.shape_basis_t, scene.expression_basis_t], axis=0).T
        dv = dv.reshape(n, 3, geo.size)
        dn = vertex_normal_tangents(v, scene.triangles, dv)
        rest = n_geometry - geo.size
        return (jnp.concatenate([dv, jnp.zeros((n, 3, rest), dv.dtype)], axis=-1),
                tuple(jnp.concatenate([c, jnp.zeros((n, rest), c.dtype)], axis=-1) for c in dn))

    def albedo_tangents(v, x, scene, hits, columns):
        """Tangents of the interpolated diffuse and specular albedo: two (3, C, ka) triples."""
        corner = tuple(scene.triangles[:, j][hits.prim_id] for j in range(3))
        geometry = GeometryParams(None, None, x[sl["angles"]], x[sl["translation"]],
                                  x[sl["focal_length"]][0])
        sc = scene._replace(camera=camera(x, scene))
        weight = barycentric_weights(geometry, sc, hits, tuple(v[c] for c in corner),
                                     orthographic)
        cols = sum(w[:, None, None] * columns[c] for w, c in zip(weight, corner))  # (C, 6, ka)
        return (tuple(cols[:, i] for i in range(3)), tuple(cols[:, 3 + i] for i in range(3)))

    @jax.jit
    def attribute_tangents(v, normals, table, x, scene, hits, dv, dn, dx):
        # The albedo table is held: its directions are the albedo coefficients', added by
        # albedo_tangents; a zero table tangent cost a gather per direction (~30 % more).
        def f(a, b, d):
            return attributes(a, b, table, d, scene, hits)
        return jax.vmap(lambda t: jax.jvp(f, (v, normals, x), t)[1],
                        in_axes=((-1, -1, 0),), out_axes=-1)((dv, dn, dx))

    @jax.jit
    def shading_tangents(attrs, x, scene, hits, dattrs, dx):
        def f(a, b):
            return shading(a, b, scene, hits)
        return jax.vmap(lambda t: jax.jvp(f, (attrs, x), t)[1],
                        in_axes=((-1, 0),), out_axes=-1)((dattrs, dx))

    @jax.jit
    def gaussian_value_and_grad(x, scene, hits, albedo_mean, albedo_basis_t, target, weight):
        """Gaussian read-out ``-sum weight ||R - target||^2 / 2`` and its gradient in ``x``.

        One reverse-mode program over all the stages: unlike the forward-mode
        Jacobian, a single pullback recomputes nothing per direction, and one
        program saves the stages' dispatches and host round trips (about 11 ms
        against 16 ms for the staged pullbacks at 250^2, one CPU thread).
        """
        def value(xx):
            v, normals = vertices(xx, scene)
            attrs = attributes(v, normals, albedo_table(xx, albedo_mean, albedo_basis_t), xx,
                               scene, hits)
            r = shading(attrs, xx, scene, hits) - target
            return -0.5 * jnp.sum(weight * r * r)
        return jax.value_and_grad(value)(x)

    @jax.jit
    def robust_value_and_grad(x, scene, hits, albedo_mean, albedo_basis_t, target, weight,
                              outlier, inv_var):
        """Robust read-out ``sum weight log(exp(-inv_var ||R - target||^2 / 2) + exp(outlier))``."""
        def value(xx):
            v, normals = vertices(xx, scene)
            attrs = attributes(v, normals, albedo_table(xx, albedo_mean, albedo_basis_t), xx,
                               scene, hits)
            r = shading(attrs, xx, scene, hits) - target
            return jnp.sum(weight * jnp.logaddexp(-0.5 * inv_var * jnp.sum(r * r, axis=0),
                                                  outlier))
        return jax.value_and_grad(value)(x)

    del ks, ke
    return (jax.jit(vertices), jax.jit(albedo_table), jax.jit(attributes), jax.jit(shading),
            jax.jit(vertex_tangents), attribute_tangents, jax.jit(albedo_tangents),
            shading_tangents, gaussian_value_and_grad, robust_value_and_grad)


_cached_stages = functools.cache(_stages)


class PixelJacobian:
    """Colours of fixed-hit pixels and their Jacobian in a :class:`SceneLayout` vector.

    Parameters
    ----------
    model : MorphableModel
    layout : SceneLayout
        The coefficient counts (at most the model's ranks).
    specular : bool
        Render the specular term (when the model has a specular part).
    background : (3,) float
        Colour of pixels whose hit mask is False.
    shadows : bool
        Cast shadows of a directional light (the hits then carry their
        visibility, ``FixedHits.shadow``).
    directional_specular_map : bool
        Scale the directional light's Blinn-Phong term by the specular albedo
        (as the renderer's).

    Notes
    -----
    ``colours`` equal the renderer's linear image at the hits' triangles
    (clamped to [0, 1], so clamped channels have zero derivatives). Compiles
    once per effect set, pixel count and layout.
    """

    def __init__(self, model: MorphableModel, layout: SceneLayout, *, specular: bool = True,
                 background=(0.0, 0.0, 0.0), shadows: bool = False,
                 directional_specular_map: bool = False):
        if layout.n_shape > model.shape.rank or layout.n_albedo > model.diffuse.rank:
            raise InputError("scene layout has more coefficients than the model")
        self.model, self.layout = model, layout
        self.shadows = bool(shadows)
        self._diff = DifferentiableModel(model, specular=specular, background=background,
                                         directional_specular_map=directional_specular_map)
        n, k = model.n_vertices, layout.n_albedo
        mean = [model.diffuse.mean.reshape(n, 3)]
        basis = [model.diffuse.scaled_basis[:, :k].reshape(n, 3, k)]
        spec = model.specular if self._diff.specular else None
        mean.append(spec.mean.reshape(n, 3) if spec is not None else np.zeros((n, 3)))
        basis.append(spec.scaled_basis[:, :k].reshape(n, 3, k) if spec is not None
                     else np.zeros((n, 3, k)))
        self._albedo_mean = jnp.asarray(np.concatenate(mean, axis=1), jnp.float32)
        columns = np.concatenate(basis, axis=1)  # (n, 6, k)
        # transposed (k, 6n), as the scene's shape basis (SceneInputs)
        self._albedo_basis_t = jnp.asarray(np.ascontiguousarray(columns.reshape(n * 6, k).T),
                                           jnp.float32)
        self._albedo_columns = jnp.asarray(columns, jnp.float32)
        sl = layout.slices()
        self._geometry = np.r_[sl["shape"], sl["expression"], sl["angles"], sl["translation"],
                               sl["focal_length"], sl["principal_point"]]
        self._shading = np.r_[sl["light"], sl["gain"], sl["contrast"], sl["offset"],
                              sl["specular_exponent"], sl["light_angles"], sl["light_intensity"]]
        self._albedo = np.r_[sl["albedo"]]
        #: Column order of the stages' Jacobian (geometry, albedo, shading entries).
        self._order = np.concatenate([self._geometry, self._albedo, self._shading])
        eye = np.eye(layout.size, dtype=np.float32)
        n_ga = self._geometry.size + self._albedo.size
        self._dx2 = jnp.asarray(eye[self._geometry])
        self._dx3 = jnp.asarray(np.concatenate([np.zeros((n_ga, layout.size), np.float32),
                                                eye[self._shading]]))

    def effects(self, params: RenderParameter) -> Effects:
        """Return the effect set the colours are formed with (colour transform always on)."""
        eff = self._diff.effects(params)._replace(color_transform=True)
        if eff.directional != self.layout.directional:
            raise InputError("the scene's directional light does not match the Jacobian's layout")
        return eff._replace(shadows=bool(self.shadows and eff.directional))

    def _prepare(self, params: RenderParameter):
        stages = _cached_stages(self.layout, self.effects(params),
                                bool(params.camera.orthographic))
        scene = self._diff.scene(params, albedo=False)
        x = jnp.asarray(self.layout.vector(params), jnp.float32)
        return stages, scene, x

    def colours(self, params: RenderParameter, hits: FixedHits) -> np.ndarray:
        """Return the (3, C) float32 linear colours of the hits at ``params``."""
        (vertices, table, attributes, shading, *_), scene, x = self._prepare(params)
        hits = hits._replace(pixels=None)
        v, normals = vertices(x, scene)
        attrs = attributes(v, normals, table(x, self._albedo_mean, self._albedo_basis_t), x,
                           scene, hits)
        return np.asarray(shading(attrs, x, scene, hits))

    def jacobian(self, params: RenderParameter,
                 hits: FixedHits) -> tuple[np.ndarray, np.ndarray]:
        """Return the colours (3, C) and their Jacobian (3, C, D) in the layout's order (float32)."""
        stages, scene, x = self._prepare(params)
        (vertices, table, attributes, shading, vertex_t, attribute_t, albedo_t,
         shading_t, *_) = stages
        hits = hits._replace(pixels=None)
        v, normals = vertices(x, scene)
        tab = table(x, self._albedo_mean, self._albedo_basis_t)
        dv, dn = vertex_t(v, scene)  # (n, 3, G), three (n, G)
        attrs = attributes(v, normals, tab, x, scene, hits)
        dattrs = attribute_t(v, normals, tab, x, scene, hits, dv, dn, self._dx2)
        diffuse_t, specular_t = albedo_t(v, x, scene, hits, self._albedo_columns)
        dattrs = _with_albedo_directions(dattrs, diffuse_t, specular_t, self._shading.size)
        colours = shading(attrs, x, scene, hits)
        jac = np.asarray(shading_t(attrs, x, scene, hits, dattrs, self._dx3))
        out = np.empty_like(jac)
        out[..., self._order] = jac
        return np.asarray(colours), out

    def gaussian_value_and_grad(self, params: RenderParameter, hits: FixedHits,
                                target: np.ndarray, weight: np.ndarray) -> tuple[float, np.ndarray]:
        """Return ``-sum weight ||R - target||^2 / 2`` over the hits and its gradient (D,) (reverse mode).

        Parameters
        ----------
        params : RenderParameter
        hits : FixedHits
        target : (3, C) float32 array (host or device)
            Target colours of the hits.
        weight : (C,) float32 array (host or device)
            Per-pixel weights, e.g. ``1 / (sigma^2 T)``, and 0 on padding.

        Returns
        -------
        (float, (D,) float64)
            The value (float32 sums) and its gradient in the layout's order: one
            pass down the stages and one back, in one compiled program (a few
            ms where the Jacobian takes a second).
        """
        stages, scene, x = self._prepare(params)
        value, grad = stages[8](x, scene, hits._replace(pixels=None), self._albedo_mean,
                                self._albedo_basis_t, target, weight)
        return float(value), np.asarray(grad, np.float64)

    def robust_value_and_grad(self, params: RenderParameter, hits: FixedHits, target: np.ndarray,
                              weight: np.ndarray, outlier: np.ndarray,
                              inv_var: float) -> tuple[float, np.ndarray]:
        """Return ``sum weight log(exp(-inv_var ||R - target||^2 / 2) + exp(outlier))`` and its gradient.

        The robust foreground's read-out (a Gaussian pixel or an occluder, the
        label summed out), up to the Gaussian's normaliser; ``outlier`` (C,)
        is each pixel's occluder log density relative to it. Otherwise as
        :meth:`gaussian_value_and_grad`.
        """
        stages, scene, x = self._prepare(params)
        value, grad = stages[9](x, scene, hits._replace(pixels=None), self._albedo_mean,
                                self._albedo_basis_t, target, weight, outlier,
                                jnp.float32(inv_var))
        return float(value), np.asarray(grad, np.float64)


@functools.partial(jax.jit, static_argnums=3)
def _with_albedo_directions(dattrs, diffuse_t, specular_t, n_shading: int):
    """Append the albedo directions (and zero shading directions) to the attribute tangents.

    Compiled: op by op, the concatenations of these (C, D) arrays took most of
    :meth:`PixelJacobian.jacobian`'s time.
    """
    def extend(t, albedo):
        zeros = jnp.zeros(t.shape[:-1] + (n_shading,), t.dtype)
        if albedo is None:
            albedo = jnp.zeros(t.shape[:-1] + (diffuse_t[0].shape[-1],), t.dtype)
        return jnp.concatenate([t, albedo, zeros], -1)

    def triple(ts, albedo):
        if ts is None:
            return None
        return tuple(extend(t, None if albedo is None else albedo[i]) for i, t in enumerate(ts))

    return dattrs._replace(normal=triple(dattrs.normal, None), view=triple(dattrs.view, None),
                           diffuse=triple(dattrs.diffuse, diffuse_t),
                           specular=triple(dattrs.specular, specular_t))
