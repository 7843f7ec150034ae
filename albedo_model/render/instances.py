"""Model instances for the renderer: float32, updated by coefficient-block deltas.

A proposal changes a block of about ten coefficients; the instance then moves
by ``U_block diag(sqrt(lambda_block)) delta``. :class:`InstanceUpdater` keeps a
transposed float32 copy of each part's scaled basis (built on first use), so
that the block is ten contiguous rows: reading 10 x 3n float32 costs about a
quarter of a millisecond for a BFM-sized part, where the same product on the
(3n, k) float64 basis with strided columns costs 2.5 ms (12 ms with a fancy
column index, as :meth:`PCAPart.update_instance` does).

Instances are float32 (what the ray caster and the shader consume). Rounding
of the incremental updates would drift over a long chain, so every
``refresh_every`` incremental updates the instance is recomputed from all
coefficients (one float32 product over the transposed basis, within a few
float32 roundings of the float64 instance; :meth:`InstanceUpdater.update`
reports the count).

:class:`ModelInstances` applies this to a morphable model: the shape +
expression instance, and the diffuse (+ specular) albedo instance as one
stacked vector when the two share coefficients.

This module imports only :mod:`albedo_model.pca`, :mod:`albedo_model.params`,
:mod:`albedo_model.model` and :mod:`albedo_model.errors`.
"""

from __future__ import annotations

import numpy as np

from albedo_model.errors import InputError
from albedo_model.model import MorphableModel
from albedo_model.params import RenderParameter
from albedo_model.pca import PCAPart

__all__ = ["InstanceUpdater", "ModelInstances", "coefficients_for"]


def coefficients_for(part: PCAPart | None, c, name: str, source: str = "parameters") -> np.ndarray:
    """``c`` as a float64 vector checked against ``part``'s rank (zeros beyond ``len(c)``).

    Parameters
    ----------
    part : PCAPart or None
        None for a part the model does not have: only all-zero ``c`` is allowed.
    c : (j,) array-like
    name : str
        Part name for messages ("shape", "colour", ...).

    Returns
    -------
    (rank,) float64 (``(0,)`` without a part)

    Raises
    ------
    InputError
        More coefficients than the rank, or non-zero ones for a missing part.
    """
    c = np.asarray(c, np.float64).reshape(-1)
    if part is None:
        if np.any(c != 0):
            raise InputError(f"{source} give {name} coefficients but the model has no {name} part")
        return c[:0]
    if c.shape[0] > part.rank:
        raise InputError(
            f"{source} give {c.shape[0]} {name} coefficients, "
            f"the model's {name} part has rank {part.rank}"
        )
    if not np.all(np.isfinite(c)):
        raise InputError(f"{source} give non-finite {name} coefficients")
    out = np.zeros(part.rank)
    out[: c.shape[0]] = c
    return out


class InstanceUpdater:
    """float32 instances of PCA parts with cheap block updates.

    An instance is a sum of *terms*; each term is a tuple of parts driven by one
    coefficient vector, whose outputs are concatenated (diffuse and specular
    albedo with shared coefficients: one (6n,) instance, one matrix-vector
    product and one device copy per update).

    Parameters
    ----------
    refresh_every : int
        Recompute an instance from scratch after this many incremental updates.
    """

    def __init__(self, refresh_every: int = 256):
        self.refresh_every = int(refresh_every)
        # ids of the parts -> (parts, (k, sum of dims) float32 scaled basis, transposed,
        # (sum of dims,) float32 mean); holding the parts keeps their ids valid
        self._basis_t: dict[tuple[int, ...], tuple[tuple, np.ndarray]] = {}

    def transposed(self, parts: tuple[PCAPart, ...]) -> np.ndarray:
        """(k, sum of dims) float32 scaled basis of stacked parts, transposed (cached)."""
        return self._stacked(parts)[1]

    def plan(self, parts: tuple[PCAPart, ...], old: np.ndarray, new: np.ndarray,
             count: int) -> tuple[np.ndarray, np.ndarray] | str | None:
        """How to move an instance of ``parts`` from ``old`` to ``new`` coefficients.

        Returns
        -------
        None
            Nothing changed.
        "full"
            Recompute from all coefficients (many changed, or ``refresh_every`` reached).
        (idx, delta) : ((j,) int32, (j,) float32)
            Add ``delta @ transposed(parts)[idx]`` to the instance.
        """
        idx = np.flatnonzero(old != new)
        if idx.size == 0:
            return None
        if count + 1 >= self.refresh_every or _many(idx.size, parts[0].rank):
            return "full"
        return idx.astype(np.int32), (new[idx] - old[idx]).astype(np.float32)

    def _stacked(self, parts: tuple[PCAPart, ...]) -> tuple[np.ndarray, np.ndarray]:
        """(sum of dims,) float32 mean and (k, sum of dims) float32 scaled basis, transposed."""
        key = tuple(id(p) for p in parts)
        entry = self._basis_t.get(key)
        if entry is None:
            bt = np.empty((parts[0].rank, sum(p.dim for p in parts)), np.float32)
            start = 0
            for p in parts:
                bt[:, start:start + p.dim] = p.scaled_basis.T
                start += p.dim
            mean = np.concatenate([p.mean for p in parts]).astype(np.float32)
            entry = self._basis_t[key] = (parts, bt, mean)
        return entry[2], entry[1]

    def instance(self, terms) -> np.ndarray:
        """float32 instance computed from all coefficients.

        ``mean + c @ basis_t`` in float32 over the transposed basis (read
        contiguously, half the bytes of float64: the product is memory-bound,
        2-6x faster than the float64 ``basis @ c``); within a few float32
        roundings of the float64 instance.

        Parameters
        ----------
        terms : sequence of (tuple of PCAPart, (rank,) float64 coefficients)
            Parts in one tuple share the coefficients and are concatenated;
            the terms are summed.

        Returns
        -------
        (sum of the parts' dims,) float32
        """
        total = None
        for parts, c in terms:
            mean, bt = self._stacked(parts)
            x = mean + np.asarray(c, np.float32) @ bt
            total = x if total is None else total + x
        return total

    def update(self, terms, inst: np.ndarray, count: int) -> tuple[np.ndarray, int]:
        """Compute the instance for the new coefficients from ``inst``, the one for the old ones.

        Parameters
        ----------
        terms : sequence of (tuple of PCAPart, old, new)
            As for :meth:`instance`, with the full old and new coefficient
            vectors ((rank,) float64, :func:`coefficients_for`).
        inst : float32 array
            The instance for the old coefficients (not modified).
        count : int
            Incremental updates behind ``inst`` since it was last computed in full.

        Returns
        -------
        inst : float32 array
            ``inst`` itself when no coefficient changed.
        count : int
            The new count (0 after a full recomputation).
        """
        changed = [(parts, np.flatnonzero(old != new), old, new) for parts, old, new in terms]
        changed = [c for c in changed if c[1].size]
        if not changed:
            return inst, count
        if count + 1 >= self.refresh_every or any(_many(idx.size, parts[0].rank)
                                                  for parts, idx, _, _ in changed):
            return self.instance([(parts, new) for parts, _, new in terms]), 0
        out = inst
        for parts, idx, old, new in changed:
            delta = (new[idx] - old[idx]).astype(np.float32)
            bt = self.transposed(parts)
            rows = bt[idx[0]:idx[-1] + 1] if idx[-1] - idx[0] + 1 == idx.size else bt[idx]
            out = out + delta @ rows
        return out, count + 1


def _many(changed: int, rank: int) -> bool:
    """Tell whether to recompute in full rather than add deltas.

    True when more than half of a part's coefficients changed, and more than a
    few (a low-rank part, e.g. 3 expression coefficients, is cheaper to update
    than to recompute with the other parts).
    """
    return changed > 8 and 2 * changed > rank


class ModelInstances:
    """The instances a renderer needs of one model, with block updates.

    Parameters
    ----------
    model : MorphableModel
    specular : bool
        Include the specular albedo (as a second row of the albedo instance).
    updater : InstanceUpdater, optional
    """

    def __init__(self, model: MorphableModel, specular: bool,
                 updater: InstanceUpdater | None = None):
        self.model = model
        self.specular = bool(specular and model.specular is not None)
        self.updater = InstanceUpdater() if updater is None else updater
        m = model
        #: Parts behind the updatable albedo rows (one coefficient vector).
        self.albedo_parts = ((m.diffuse, m.specular) if self.specular and m.shared_albedo
                             else (m.diffuse,))

    def _shape_terms(self, params: RenderParameter) -> list:
        m = self.model
        terms = [((m.shape,), coefficients_for(m.shape, params.momo.shape, "shape"))]
        expr = coefficients_for(m.expression, params.momo.expression, "expression")
        if m.expression is not None:
            terms.append(((m.expression,), expr))
        return terms

    def shape(self, params: RenderParameter) -> np.ndarray:
        """(3n,) float32 shape + expression instance (model frame, interleaved)."""
        return self.updater.instance(self._shape_terms(params))

    def update_shape(self, old: RenderParameter, new: RenderParameter, inst: np.ndarray,
                     count: int) -> tuple[np.ndarray, int]:
        """:meth:`InstanceUpdater.update` of the shape instance ``inst`` of ``old``."""
        terms = [(parts, a, b) for (parts, a), (_, b) in
                 zip(self._shape_terms(old), self._shape_terms(new))]
        return self.updater.update(terms, inst, count)

    def albedo(self, params: RenderParameter) -> np.ndarray:
        """(1, 3n) diffuse or (2, 3n) diffuse + specular float32 instance."""
        m = self.model
        c = coefficients_for(m.diffuse, params.momo.albedo, "colour")
        flat = self.updater.instance([(self.albedo_parts, c)]).reshape(len(self.albedo_parts), -1)
        if self.specular and not m.shared_albedo:
            # an independent specular albedo has no coefficients in a scene: its mean
            return np.stack([flat[0], m.specular.mean.astype(np.float32)])
        return flat

    def albedo_plan(self, old: RenderParameter, new: RenderParameter, count: int):
        """:meth:`InstanceUpdater.plan` for the albedo rows of :attr:`albedo_parts`."""
        m = self.model
        return self.updater.plan(self.albedo_parts,
                                 coefficients_for(m.diffuse, old.momo.albedo, "colour"),
                                 coefficients_for(m.diffuse, new.momo.albedo, "colour"), count)
