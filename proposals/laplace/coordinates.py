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
* the focal length, the distance ``d = view_z - t_z`` and the specular
  exponent are positive and carry log-normal priors: their coordinate is the
  logarithm (``x = exp(u)``, ``t_z = view_z - exp(u)``), in which the priors are
  Gaussian and the focal-length/distance ridge (the image size ``f / d``) is a
  straight line.

A move drawn in ``u`` has, in the parameters as stored, the transition
density of ``u`` times ``|du/dx|``; :meth:`SamplingCoordinates.log_jacobian`
is ``log |dx/du|`` (the sum of the log-scale entries), so the
Metropolis-Hastings ratio of a move ``u -> u'`` is its ratio in ``u`` plus
``log_jacobian(u') - log_jacobian(u)``.

This module imports :mod:`albedo_model.errors`, :mod:`albedo_model.params` and
:mod:`albedo_model.scene_vector`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from albedo_model.errors import InputError
from albedo_model.params import Block, RenderParameter
from albedo_model.scene_vector import SceneLayout

__all__ = ["HELD", "LOG_SCALE", "SamplingCoordinates", "entry_blocks"]

#: Scene entries held fixed by the Gaussian moves (see the module notes).
HELD = ("gain", "principal_point")
#: Scene entries whose coordinate is a logarithm.
LOG_SCALE = ("focal_length", "distance", "specular_exponent")

_BLOCK_OF = {"shape": Block.SHAPE, "expression": Block.EXPRESSION, "angles": Block.POSE,
             "translation": Block.POSE, "focal_length": Block.CAMERA,
             "principal_point": Block.CAMERA, "light": Block.LIGHT,
             "gain": Block.COLOR_TRANSFORM, "contrast": Block.COLOR_TRANSFORM,
             "offset": Block.COLOR_TRANSFORM, "specular_exponent": Block.SPECULAR_EXPONENT,
             "albedo": Block.ALBEDO}


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
    names: tuple[str, ...] = field(init=False)
    touches: Block = field(init=False)
    _keep: np.ndarray = field(init=False, repr=False)
    _log: np.ndarray = field(init=False, repr=False)
    _tz: int = field(init=False, repr=False)

    def __post_init__(self) -> None:
        """Choose the sampled entries and their scales."""
        slices = self.layout.slices()
        unknown = set(self.held) - set(slices)
        if unknown:
            raise InputError(f"unknown scene entries to hold: {sorted(unknown)}")
        keep, names, log, touches = [], [], [], Block.NONE
        tz = slices["translation"].start + 2
        for entry, sl in slices.items():
            if entry in self.held or not (_BLOCK_OF[entry] & self.blocks):
                continue
            for k, i in enumerate(range(sl.start, sl.stop)):
                keep.append(i)
                is_log = (entry in LOG_SCALE) or (i == tz)
                log.append(is_log)
                label = "distance" if i == tz else entry
                names.append(f"log_{label}" if is_log else
                             (entry if sl.stop - sl.start == 1 else f"{entry}.{k}"))
                touches |= _BLOCK_OF[entry]
        if not keep:
            raise InputError("no scene entry is sampled")
        object.__setattr__(self, "_keep", np.asarray(keep, np.int64))
        object.__setattr__(self, "_log", np.asarray(log, bool))
        object.__setattr__(self, "_tz", tz)
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
        v = np.asarray(x, np.float64)[self._keep].copy()
        dist = self._keep == self._tz
        v[dist] = self._view_z() - v[dist]
        if np.any(v[self._log] <= 0):
            raise InputError("focal length, distance and specular exponent must be positive")
        v[self._log] = np.log(v[self._log])
        return v

    def x_of_u(self, u: np.ndarray, x0: np.ndarray | None = None) -> np.ndarray:
        """Return the scene vector of ``u`` (held entries from ``x0``, default the template's)."""
        u = np.asarray(u, np.float64).reshape(-1)
        if u.shape[0] != self.size:
            raise InputError(f"coordinate vector has {u.shape[0]} entries, expected {self.size}")
        x = (self.layout.vector(self.template) if x0 is None else np.array(x0, np.float64))
        v = u.copy()
        v[self._log] = np.exp(v[self._log])
        dist = self._keep == self._tz
        v[dist] = self._view_z() - v[dist]
        x[self._keep] = v
        return x

    def u_of(self, params: RenderParameter) -> np.ndarray:
        """Return the coordinates of ``params``."""
        return self.u_of_x(self.layout.vector(params))

    def params_of(self, u: np.ndarray, base: RenderParameter | None = None) -> RenderParameter:
        """Return the parameters of ``u`` (everything else from ``base``, default the template)."""
        base = self.template if base is None else base
        return self.layout.with_vector(base, self.x_of_u(u, self.layout.vector(base)))

    def dx_du(self, u: np.ndarray) -> np.ndarray:
        """Return ``dx_i / du_i`` of each coordinate's scene entry (the map is elementwise)."""
        u = np.asarray(u, np.float64)
        return np.where(self._log, np.exp(np.where(self._log, u, 0.0)), 1.0) * self._signs()

    def d2x_du2(self, u: np.ndarray) -> np.ndarray:
        """Return ``d^2 x_i / du_i^2`` (nonzero for the log-scale entries)."""
        u = np.asarray(u, np.float64)
        return np.where(self._log, np.exp(np.where(self._log, u, 0.0)), 0.0) * self._signs()

    def log_jacobian(self, u: np.ndarray) -> float:
        """Return ``log |dx/du|``: the sum of the log-scale coordinates."""
        return float(np.sum(np.asarray(u, np.float64)[self._log]))

    def gradient(self, gradient_x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Return the gradient in ``u`` of ``log p(x(u)) + log |dx/du|`` from that of ``log p`` in x."""
        g = np.asarray(gradient_x, np.float64)[self._keep]
        return self.dx_du(u) * g + self._log.astype(np.float64)

    def to_coordinates(self, gradient_x: np.ndarray, precision_x: np.ndarray, u: np.ndarray,
                       *, second_order: np.ndarray | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
        """Turn a log density's gradient and precision in ``x`` into those in ``u``.

        ``gradient_x`` (D,) and ``precision_x`` (D, D) (the negative Hessian, or
        a Gauss-Newton approximation of it) are of ``log p(x)``; the result is of
        ``log p(x(u)) + log |dx/du|``. The chain rule's second-order term
        ``-g_i d^2x_i/du_i^2`` of the log-scale entries uses ``second_order``
        (default ``gradient_x``): pass the gradient of the terms whose precision
        is exact (the prior: a log-normal prior in x is then exactly Gaussian in
        u) and leave out a Gauss-Newton likelihood's, whose second-order terms
        are dropped anyway (with them, a point off the mode can make the
        precision indefinite).
        """
        d = self.dx_du(u)
        g = np.asarray(gradient_x, np.float64)[self._keep]
        h = np.asarray(precision_x, np.float64)[np.ix_(self._keep, self._keep)]
        grad = d * g + self._log.astype(np.float64)
        prec = h * np.outer(d, d)
        g2 = g if second_order is None else np.asarray(second_order, np.float64)[self._keep]
        prec[np.diag_indices_from(prec)] -= g2 * self.d2x_du2(u)
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
