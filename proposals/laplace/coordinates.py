"""The coordinates Gaussian moves work in: the sampled scene entries, positive ones on a log scale.

A Gaussian approximation of the posterior (:mod:`proposals.laplace.moves`) is only
as good as the coordinates it is written in. :class:`SamplingCoordinates`
maps a vector ``u`` to scene parameters through a
:class:`~albedo_model.scene_vector.SceneLayout` vector ``x``:

* the **sampled** entries are those of a fit's parameter blocks; the colour
  transform's **gain** and the **principal point** are held at their values
  (:data:`HELD`): the gain is exactly confounded with the SH light's colour
  (``gain_c L_c`` is all the image sees when the contrast is 1), and the
  principal point with the pose translation and rotation (a shift of the image
  centre is a translation of the head up to a sub-degree perspective turn), so
  sampling them adds directions that only their priors bound, along curved
  ridges no Gaussian follows;
* the focal length, the distance ``d = view_z - t_z``, the specular
  exponent and the directional light's strengths are positive and carry
  log-normal priors: their coordinate is the
  logarithm (``x = exp(u)``, ``t_z = view_z - exp(u)``), in which the priors are
  Gaussian and the focal-length/distance ridge (the image size ``f / d``) is a
  straight line;
* with ``inverse_distance`` the distance's coordinate is ``d_0 / d`` (``d_0``
  the template's distance) in place of ``log d``: the perspective's effect on
  the image is, to first order, the vertices' depths times ``1 / d``, so the
  ridge along which the shape, the pose and the image size make up for a
  change of the distance is straight in ``1 / d`` and bent in ``log d``
  (over the 2 sds of a held-out face's distance posterior, +-35 % in ``d``,
  ``exp(-u)`` departs from a line by ~17 %, as much as that ridge's width);
* given an :class:`~proposals.laplace.image_scale.ImageScale` (``scale``), the
  focal length's coordinate is the log **image size** of the face,
  ``log f + scale.log_radius(x)``, in place of ``log f``: the image pins it
  directly, and the ridge that ``log f`` traces against the distance, the
  shape's size and the translation (curved in those coordinates) becomes a
  coordinate axis. ``f`` then follows from the other entries
  (``f = exp(u_f - log_radius(x))``, a triangular map), and ``dx/du`` is the
  elementwise map plus one row.

A move drawn in ``u`` has, in the parameters as stored, the transition
density of ``u`` times ``|du/dx|``; :meth:`SamplingCoordinates.log_jacobian`
is ``log |dx/du|`` (the sum of the log-scale entries, plus ``log d_0 - 2 log u``
for an inverse distance ``u``, which is -inf where ``u <= 0``), so the
Metropolis-Hastings ratio of a move ``u -> u'`` is its ratio in ``u`` plus
``log_jacobian(u') - log_jacobian(u)``.

This module imports :mod:`albedo_model.errors`, :mod:`albedo_model.params`,
:mod:`albedo_model.scene_vector` and :mod:`proposals.laplace.image_scale`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from albedo_model.errors import InputError
from albedo_model.params import Block, RenderParameter
from albedo_model.scene_vector import SceneLayout
from proposals.laplace.image_scale import ImageScale

__all__ = ["HELD", "LOG_SCALE", "SamplingCoordinates", "entry_blocks"]

#: Scene entries held fixed by the Gaussian moves (see the module notes).
HELD = ("gain", "principal_point")
#: Scene entries whose coordinate is a logarithm.
LOG_SCALE = ("focal_length", "distance", "specular_exponent", "light_intensity")

_BLOCK_OF = {"shape": Block.SHAPE, "expression": Block.EXPRESSION, "angles": Block.POSE,
             "translation": Block.POSE, "focal_length": Block.CAMERA,
             "principal_point": Block.CAMERA, "light": Block.LIGHT,
             "gain": Block.COLOR_TRANSFORM, "contrast": Block.COLOR_TRANSFORM,
             "offset": Block.COLOR_TRANSFORM, "specular_exponent": Block.SPECULAR_EXPONENT,
             "albedo": Block.ALBEDO, "light_angles": Block.DIRECTIONAL_ANGLES,
             "light_intensity": Block.DIRECTIONAL_STRENGTH}


def entry_blocks() -> dict[str, Block]:
    """Return scene-layout entry name -> the parameter block it belongs to."""
    return dict(_BLOCK_OF)


@dataclass(frozen=True, eq=False)
class SamplingCoordinates:
    """``u <-> RenderParameter`` for one fit (see the module notes).

    Parameters
    ----------
    layout : SceneLayout
    template : RenderParameter
        Supplies every field not in ``u`` (view, image size, sensor, held entries).
    blocks : Block
        The parameter blocks sampled (entries of other blocks are held too).
    held : sequence of str
        Scene entries held at the template's values (default :data:`HELD`).
    scale : ImageScale, optional
        Sample the log image size in place of the log focal length (see the
        module notes); same layout as ``layout``.
    inverse_distance : bool
        Sample ``d_0 / d`` in place of ``log d`` (see the module notes).

    Attributes
    ----------
    names : tuple of str
        One name per coordinate (``"shape.3"``, ``"log_focal_length"``, ...).
    touches : Block
        The blocks a move of every coordinate changes.
    """

    layout: SceneLayout
    template: RenderParameter
    blocks: Block = Block.ALL
    held: tuple[str, ...] = HELD
    scale: ImageScale | None = None
    inverse_distance: bool = False
    names: tuple[str, ...] = field(init=False)
    touches: Block = field(init=False)
    _keep: np.ndarray = field(init=False, repr=False)
    _log: np.ndarray = field(init=False, repr=False)
    _tz: int = field(init=False, repr=False)
    _f: int | None = field(init=False, repr=False)
    _inv: np.ndarray = field(init=False, repr=False)
    _d0: float = field(init=False, repr=False)

    def __post_init__(self) -> None:
        """Choose the sampled entries and their scales."""
        slices = self.layout.slices()
        unknown = set(self.held) - set(slices)
        if unknown:
            raise InputError(f"unknown scene entries to hold: {sorted(unknown)}")
        keep, names, log, touches = [], [], [], Block.NONE
        tz = slices["translation"].start + 2
        inverse = self.inverse_distance
        for entry, sl in slices.items():
            if entry in self.held or not (_BLOCK_OF[entry] & self.blocks):
                continue
            for k, i in enumerate(range(sl.start, sl.stop)):
                keep.append(i)
                is_log = (entry in LOG_SCALE) or (i == tz and not inverse)
                log.append(is_log)
                if i == tz:
                    name = "inverse_distance" if inverse else "log_distance"
                else:
                    name = f"log_{entry}" if is_log else entry
                names.append(name if sl.stop - sl.start == 1 or i == tz else f"{name}.{k}")
                touches |= _BLOCK_OF[entry]
        if not keep:
            raise InputError("no scene entry is sampled")
        f_entry = slices["focal_length"].start
        f_pos = keep.index(f_entry) if (self.scale is not None and f_entry in keep) else None
        if self.scale is not None:
            if self.scale.layout != self.layout:
                raise InputError("the image scale's scene layout differs from the coordinates'")
            if f_pos is not None:
                names[f_pos] = "log_image_size"
        object.__setattr__(self, "_f", f_pos)
        object.__setattr__(self, "_keep", np.asarray(keep, np.int64))
        object.__setattr__(self, "_log", np.asarray(log, bool))
        object.__setattr__(self, "_tz", tz)
        object.__setattr__(self, "_inv", (self._keep == tz) & inverse)
        d0 = self._view_z() - float(self.layout.vector(self.template)[tz])
        if inverse and not d0 > 0:
            raise InputError(f"the template's distance must be positive, got {d0}")
        object.__setattr__(self, "_d0", d0)
        object.__setattr__(self, "names", tuple(names))
        object.__setattr__(self, "touches", touches)

    @property
    def size(self) -> int:
        """Number of coordinates."""
        return int(self._keep.size)

    @property
    def scene_indices(self) -> np.ndarray:
        """Index of each coordinate's entry in the scene vector (the layout's)."""
        return self._keep.copy()

    def _view_z(self) -> float:
        return float(self.template.view.translation[2])

    def _signs(self) -> np.ndarray:
        """+1, or -1 for the distance (``t_z = view_z - exp(u)``)."""
        return np.where(self._keep == self._tz, -1.0, 1.0)

    def u_of_x(self, x: np.ndarray) -> np.ndarray:
        """Return the coordinates of a scene vector (log-scale entries must be positive)."""
        x = np.asarray(x, np.float64)
        v = x[self._keep].copy()
        dist = self._keep == self._tz
        v[dist] = self._view_z() - v[dist]
        if np.any(v[self._log | self._inv] <= 0):
            raise InputError("focal length, distance and specular exponent must be positive")
        v[self._log] = np.log(v[self._log])
        v[self._inv] = self._d0 / v[self._inv]
        if self._f is not None:
            v[self._f] += self.scale.log_radius(x)
        return v

    def x_of_u(self, u: np.ndarray, x0: np.ndarray | None = None) -> np.ndarray:
        """Return the scene vector of ``u`` (held entries from ``x0``, default the template's)."""
        u = np.asarray(u, np.float64).reshape(-1)
        if u.shape[0] != self.size:
            raise InputError(f"coordinate vector has {u.shape[0]} entries, expected {self.size}")
        x = (self.layout.vector(self.template) if x0 is None else np.array(x0, np.float64))
        v = u.copy()
        v[self._log] = np.exp(v[self._log])
        with np.errstate(divide="ignore"):  # u <= 0 has density 0 (log_jacobian -inf)
            v[self._inv] = self._d0 / v[self._inv]
        dist = self._keep == self._tz
        v[dist] = self._view_z() - v[dist]
        x[self._keep] = v
        if self._f is not None:  # f from the image size and the other entries
            x[self._keep[self._f]] = np.exp(u[self._f] - self.scale.log_radius(x))
        return x

    def u_of(self, params: RenderParameter) -> np.ndarray:
        """Return the coordinates of ``params``."""
        return self.u_of_x(self.layout.vector(params))

    def params_of(self, u: np.ndarray, base: RenderParameter | None = None) -> RenderParameter:
        """Return the parameters of ``u`` (everything else from ``base``, default the template)."""
        base = self.template if base is None else base
        return self.layout.with_vector(base, self.x_of_u(u, self.layout.vector(base)))

    def _log_values(self, u: np.ndarray, x: np.ndarray | None = None) -> np.ndarray:
        """Return the log of each log-scale entry's value (``u`` itself but for the image size).

        ``x`` is ``x_of_u(u)`` when the caller has it (read only with ``scale``).
        """
        u = np.asarray(u, np.float64)
        out = np.where(self._log, u, 0.0)
        if self._f is not None:
            x = self.x_of_u(u) if x is None else x
            out[self._f] = np.log(x[self._keep[self._f]])
        return out

    def _diagonal(self, u: np.ndarray, x: np.ndarray | None = None) -> np.ndarray:
        out = np.where(self._log, np.exp(self._log_values(u, x)), 1.0) * self._signs()
        if self._inv.any():  # t_z = view_z - d0 / u
            ui = np.asarray(u, np.float64)[self._inv]
            out[self._inv] = self._d0 / (ui * ui)
        return out

    def _second(self, u: np.ndarray, diag: np.ndarray) -> np.ndarray:
        """Return ``d^2 x_i / du_i^2`` given the diagonal of ``dx/du``."""
        out = np.where(self._log, diag, 0.0)
        if self._inv.any():
            out[self._inv] = -2.0 * diag[self._inv] / np.asarray(u, np.float64)[self._inv]
        return out

    def _jacobian_gradient(self, u: np.ndarray) -> np.ndarray:
        """Return ``d log |dx/du| / du`` (1 per log-scale entry, ``-2 / u`` for an inverse distance)."""
        out = self._log.astype(np.float64)
        if self._inv.any():
            out[self._inv] = -2.0 / np.asarray(u, np.float64)[self._inv]
        return out

    def _scale_terms(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return the diagonal of ``dx/du`` and ``d log_radius / du`` (0 at ``f``), one map of ``u``."""
        x = self.x_of_u(u)
        diag = self._diagonal(u, x)
        _, gx = self.scale.value_and_gradient(x)
        c = diag * gx[self._keep]
        c[self._f] = 0.0
        return diag, c

    def dx_du(self, u: np.ndarray) -> np.ndarray:
        """Return the diagonal ``dx_i / du_i`` of the map (the whole Jacobian without ``scale``)."""
        return self._diagonal(u)

    def d2x_du2(self, u: np.ndarray) -> np.ndarray:
        """Return ``d^2 x_i / du_i^2`` (nonzero for the log-scale entries)."""
        return self._second(u, self._diagonal(u))

    def _jacobian_of(self, diag: np.ndarray, c: np.ndarray | None) -> np.ndarray:
        jac = np.diag(diag)
        if c is not None:
            jac[self._f] -= diag[self._f] * c
        return jac

    def jacobian(self, u: np.ndarray) -> np.ndarray:
        """Return ``dx / du`` (d, d) between the coordinates and their scene entries."""
        if self._f is None:
            return self._jacobian_of(self._diagonal(u), None)
        return self._jacobian_of(*self._scale_terms(u))

    def log_jacobian(self, u: np.ndarray) -> float:
        """Return ``log |dx/du|``: the sum of the log-scale entries' logarithms.

        An inverse distance ``u`` adds ``log d0 - 2 log u`` (-inf where ``u <= 0``).
        """
        out = float(np.sum(self._log_values(u)))
        if self._inv.any():
            ui = float(np.asarray(u, np.float64)[self._inv][0])
            out += math.log(self._d0) - 2.0 * math.log(ui) if ui > 0 else -math.inf
        return out

    def _gradient_of(self, g: np.ndarray, diag: np.ndarray, c: np.ndarray | None,
                     u: np.ndarray) -> np.ndarray:
        out = diag * g + self._jacobian_gradient(u)
        if c is not None:
            out -= (g[self._f] * diag[self._f] + 1.0) * c
        return out

    def gradient(self, gradient_x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Return the gradient in ``u`` of ``log p(x(u)) + log |dx/du|`` from that of ``log p`` in x."""
        g = np.asarray(gradient_x, np.float64)[self._keep]
        if self._f is None:
            return self._gradient_of(g, self._diagonal(u), None, u)
        return self._gradient_of(g, *self._scale_terms(u), u)

    def to_coordinates(self, gradient_x: np.ndarray, precision_x: np.ndarray, u: np.ndarray,
                       *, second_order: np.ndarray | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
        """Turn a log density's gradient and precision in ``x`` into those in ``u``.

        ``gradient_x`` (D,) and ``precision_x`` (D, D) (the negative Hessian, or
        a Gauss-Newton approximation of it) are of ``log p(x)``; the result is of
        ``log p(x(u)) + log |dx/du|``. The chain rule's second-order term
        ``-g_i d^2x_i/du^2`` of the log-scale entries uses ``second_order``
        (default ``gradient_x``): pass the gradient of the terms whose precision
        is exact (the prior: a log-normal prior in x is then exactly Gaussian in
        u) and leave out a Gauss-Newton likelihood's, whose second-order terms
        are dropped anyway (with them, a point off the mode can make the
        precision indefinite). With ``scale`` the image size's term is
        ``-g_f f a a^T`` (``a = d log f / du``); the log radius's own curvature
        is left out (small: the radius is nearly linear in the entries).
        """
        g = np.asarray(gradient_x, np.float64)[self._keep]
        h = np.asarray(precision_x, np.float64)[np.ix_(self._keep, self._keep)]
        diag, c = self._scale_terms(u) if self._f is not None else (self._diagonal(u), None)
        jac = self._jacobian_of(diag, c)
        grad = self._gradient_of(g, diag, c, u)
        prec = jac.T @ h @ jac
        g2 = g if second_order is None else np.asarray(second_order, np.float64)[self._keep]
        d2 = self._second(u, diag)
        if self._inv.any():  # log |dx/du| = log d0 - 2 log u is curved too
            ui = np.asarray(u, np.float64)[self._inv]
            prec[self._inv, self._inv] -= 2.0 / (ui * ui)
        if self._f is None:
            prec[np.diag_indices_from(prec)] -= g2 * d2
        else:
            second = g2 * d2
            second[self._f] = 0.0
            prec[np.diag_indices_from(prec)] -= second
            a = jac[self._f] / jac[self._f, self._f]
            prec -= g2[self._f] * d2[self._f] * np.outer(a, a)
        return grad, prec

    def blocks_of(self, mask: np.ndarray) -> Block:
        """Return the blocks of the coordinates selected by a boolean ``mask``."""
        names = list(self.layout.sizes())
        starts = np.cumsum([0] + list(self.layout.sizes().values()))
        out = Block.NONE
        for i in self._keep[np.asarray(mask, bool)]:
            entry = names[int(np.searchsorted(starts, i, side="right")) - 1]
            out |= _BLOCK_OF[entry]
        return out
