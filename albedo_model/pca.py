"""Probabilistic PCA parts of a morphable model.

A :class:`PCAPart` is the linear Gaussian model ``x = mean + U diag(sqrt(var)) c``
with standard-normal coefficients ``c`` (scalismo's discrete low-rank Gaussian
process). Shape, expression, diffuse and specular albedo are all PCA parts.

A part may carry a per-row *residual variance*: the variance of what its span
cannot represent (probabilistic PCA's noise term, made per row, i.e. per
vertex and channel), estimated out of sample when the model is built (see
:mod:`pipeline.modelling.residual_variance`). It is ``None`` when unknown
(AlbedoMM and BFM files do not have it). Rendering never uses it; posterior
predictive intervals of the albedo do.

This module imports only :mod:`albedo_model.errors`.
"""

from __future__ import annotations

import dataclasses
from functools import cached_property

import numpy as np

from albedo_model.errors import InputError

__all__ = ["PCAPart", "pca_from_data"]


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


def _checked_residual(residual: np.ndarray, dim: int) -> np.ndarray:
    r = np.asarray(residual)
    if r.shape != (dim,) or r.dtype.kind != "f":
        raise InputError(f"PCA residual variance must be a float array of shape ({dim},), "
                         f"got {r.dtype} {r.shape}")
    if not np.all(np.isfinite(r)) or np.any(r < 0):
        raise InputError("PCA residual variance must be finite and non-negative")
    return r


@dataclasses.dataclass(frozen=True, eq=False)
class PCAPart:
    """A PCA (PPCA) model over a flat data vector.

    Parameters
    ----------
    mean : (d,) float array
        Mean vector, per-vertex interleaved (x0 y0 z0 x1 ...) for mesh data.
    basis : (d, k) float array
        Orthonormal columns ``U``.
    variance : (k,) float array
        Eigenvalues ``lambda``; a column's standard deviation is ``sqrt(lambda)``.
    noise_variance : float
        Isotropic PPCA noise variance (not used when rendering).
    residual_variance : (d,) float array, optional
        Per-row variance of the data outside the span (out-of-sample residual
        of the model's rank); ``None`` when unknown. Not used when rendering.

    Notes
    -----
    Arrays are stored read-only; derived arrays (``scaled_basis``) are cached.
    Instances are immutable: :meth:`truncate` returns a new part.
    """

    mean: np.ndarray
    basis: np.ndarray
    variance: np.ndarray
    noise_variance: float = 0.0
    residual_variance: np.ndarray | None = None

    def __post_init__(self) -> None:
        """Validate the shapes and values and store read-only arrays."""
        mean = np.asarray(self.mean)
        basis = np.asarray(self.basis)
        variance = np.asarray(self.variance)
        if mean.ndim != 1:
            raise InputError(f"PCA mean must be 1-D, got shape {mean.shape}")
        if basis.ndim != 2 or basis.shape[0] != mean.shape[0]:
            raise InputError(
                f"PCA basis must have shape ({mean.shape[0]}, k), got {basis.shape}"
            )
        if variance.shape != (basis.shape[1],):
            raise InputError(
                f"PCA variance must have shape ({basis.shape[1]},), got {variance.shape}"
            )
        for name, a in (("mean", mean), ("basis", basis), ("variance", variance)):
            if not np.all(np.isfinite(a)):
                raise InputError(f"PCA {name} contains NaN or infinite values")
        if np.any(variance < 0):
            raise InputError("PCA variances must be non-negative")
        if self.residual_variance is not None:
            object.__setattr__(self, "residual_variance",
                               _readonly(_checked_residual(self.residual_variance, mean.shape[0])))
        object.__setattr__(self, "mean", _readonly(mean))
        object.__setattr__(self, "basis", _readonly(basis))
        object.__setattr__(self, "variance", _readonly(variance))
        object.__setattr__(self, "noise_variance", float(self.noise_variance))

    # -- sizes ---------------------------------------------------------------
    @property
    def dim(self) -> int:
        """Length ``d`` of the data vector."""
        return int(self.mean.shape[0])

    @property
    def rank(self) -> int:
        """Number of components ``k``."""
        return int(self.basis.shape[1])

    # -- derived (cached) ----------------------------------------------------
    @cached_property
    def std(self) -> np.ndarray:
        """``sqrt(variance)``, shape (k,)."""
        return _readonly(np.sqrt(self.variance))

    @cached_property
    def scaled_basis(self) -> np.ndarray:
        """``U diag(sqrt(lambda))``, shape (d, k), same dtype as the basis."""
        return _readonly((self.basis * self.std.astype(self.basis.dtype)).astype(self.basis.dtype))

    # -- instances -----------------------------------------------------------
    def _pad(self, coefficients: np.ndarray | None) -> np.ndarray:
        c = np.zeros(self.rank) if coefficients is None else np.asarray(coefficients, float)
        if c.ndim != 1:
            raise InputError(f"coefficients must be 1-D, got shape {c.shape}")
        if c.shape[0] > self.rank:
            raise InputError(f"{c.shape[0]} coefficients given for a rank-{self.rank} part")
        if not np.all(np.isfinite(c)):
            raise InputError("coefficients contain NaN or infinite values")
        if c.shape[0] < self.rank:
            c = np.concatenate([c, np.zeros(self.rank - c.shape[0])])
        return c

    def instance(self, coefficients: np.ndarray | None = None) -> np.ndarray:
        """Return the data vector for standard-normal coefficients.

        Parameters
        ----------
        coefficients : (j,) array, j <= k, optional
            Missing trailing coefficients are zero; ``None`` gives the mean.

        Returns
        -------
        (d,) float64 array
            ``mean + U diag(sqrt(lambda)) c``.
        """
        j = 0 if coefficients is None else int(np.asarray(coefficients).reshape(-1).shape[0])
        c = self._pad(coefficients)
        return self._mean64 + self._leading64(j) @ c[:j]

    @cached_property
    def _mean64(self) -> np.ndarray:
        return _readonly(self.mean.astype(np.float64))

    def _leading64(self, j: int) -> np.ndarray:
        """Return the first ``j`` scaled basis columns as a contiguous float64 array (kept per j).

        The float64 product ``scaled_basis @ c`` without converting the float32
        basis on every call (3 ms per instance of a 19k-vertex head). One array
        per width: the same inputs always meet the same memory layout, so the
        BLAS product, and every chain built on it, is reproducible bit for bit.
        """
        cache = self.__dict__.setdefault("_leading_cache", {})
        if j not in cache:
            cache[j] = _readonly(np.ascontiguousarray(self.scaled_basis[:, :j],
                                                      dtype=np.float64))
        return cache[j]

    def update_instance(
        self,
        instance: np.ndarray,
        old: np.ndarray,
        new: np.ndarray,
        index: slice | np.ndarray | None = None,
    ) -> np.ndarray:
        """Instance for ``new`` coefficients from the instance for ``old`` ones.

        Only the columns in ``index`` (default: where ``old != new``) are touched,
        so a 10-coefficient block update costs ``d x 10`` instead of ``d x k``.

        Parameters
        ----------
        instance : (d,) array
            ``self.instance(old)``.
        old, new : (j,) arrays
            Coefficient vectors before and after (padded like :meth:`instance`).
        index : slice or int array, optional
            Columns that may differ.

        Returns
        -------
        (d,) float64 array
            Equal (to rounding) to ``self.instance(new)``.
        """
        old_c, new_c = self._pad(old), self._pad(new)
        if index is None:
            index = np.flatnonzero(old_c != new_c)
            if index.size == 0:
                return np.asarray(instance, np.float64).copy()
        delta = new_c[index] - old_c[index]
        return np.asarray(instance, np.float64) + self.scaled_basis[:, index] @ delta

    def project(self, data: np.ndarray, *, regularization: float | None = None) -> np.ndarray:
        """Coefficients that best explain ``data`` (MAP under the N(0, I) prior).

        Parameters
        ----------
        data : (d,) or (n, d) array
            Data vectors in the layout of :attr:`mean`.
        regularization : float, optional
            PPCA noise variance used in the posterior mean; defaults to
            :attr:`noise_variance`. With 0 this is the orthogonal projection.

        Returns
        -------
        (k,) or (n, k) array
            ``c = sqrt(lambda) / (lambda + sigma^2) * U^T (x - mean)``.
        """
        x = np.asarray(data, np.float64)
        if x.shape[-1] != self.dim:
            raise InputError(f"data has length {x.shape[-1]}, the part has dimension {self.dim}")
        s2 = self.noise_variance if regularization is None else float(regularization)
        proj = (x - self.mean) @ self.basis.astype(np.float64)
        lam = self.variance.astype(np.float64)
        denom = lam + s2
        scale = np.divide(np.sqrt(lam), denom, out=np.zeros_like(lam), where=denom > 0)
        return proj * scale

    def sample(self, rng: np.random.Generator, n: int | None = None) -> np.ndarray:
        """Random instances (coefficients drawn from N(0, I), no noise).

        Parameters
        ----------
        rng : numpy.random.Generator
        n : int, optional
            Number of samples; ``None`` returns a single (d,) instance.

        Returns
        -------
        (d,) or (n, d) float64 array
        """
        if n is None:
            return self.instance(rng.standard_normal(self.rank))
        c = rng.standard_normal((n, self.rank))
        return self.mean.astype(np.float64) + c @ self.scaled_basis.T

    def truncate(self, k: int) -> PCAPart:
        """Return the part restricted to its first ``k`` components.

        A residual variance grows by the variance of the dropped components,
        ``sum_{j >= k} U_ij^2 lambda_j`` per row: what they modelled is now
        outside the span (their in-sample variance stands in for an
        out-of-sample estimate at the smaller rank).
        """
        if not 0 <= k <= self.rank:
            raise InputError(f"cannot truncate a rank-{self.rank} part to {k} components")
        residual = self.residual_variance
        if residual is not None and k < self.rank:
            dropped = (self.basis[:, k:].astype(np.float64) ** 2) @ self.variance[k:].astype(
                np.float64)
            residual = (residual.astype(np.float64) + dropped).astype(residual.dtype)
        return PCAPart(self.mean, self.basis[:, :k], self.variance[:k], self.noise_variance,
                       residual)

    def with_residual_variance(self, residual_variance: np.ndarray | None) -> PCAPart:
        """Return the same part with ``residual_variance`` (``None`` removes it)."""
        return dataclasses.replace(self, residual_variance=residual_variance)

    def marginal_std(self, *, include_noise: bool = False,
                     include_residual: bool = False) -> np.ndarray:
        """Per-row marginal standard deviation of the model distribution.

        Parameters
        ----------
        include_noise : bool
            Add the isotropic :attr:`noise_variance`.
        include_residual : bool
            Add the per-row :attr:`residual_variance` (nothing when it is ``None``).

        Returns
        -------
        (d,) float64 array
            ``sqrt(sum_j U_ij^2 lambda_j [+ sigma^2] [+ r_i])``; for an uncertainty
            map of per-vertex colours reshape to (n, 3).
        """
        var = (self.basis.astype(np.float64) ** 2) @ self.variance.astype(np.float64)
        if include_noise:
            var = var + self.noise_variance
        if include_residual and self.residual_variance is not None:
            var = var + self.residual_variance.astype(np.float64)
        return np.sqrt(var)

    def with_dtype(self, dtype: np.dtype) -> PCAPart:
        """Return the same part with mean, basis (and residual variance) cast to ``dtype``."""
        residual = None if self.residual_variance is None else self.residual_variance.astype(dtype)
        return PCAPart(
            self.mean.astype(dtype), self.basis.astype(dtype), self.variance, self.noise_variance,
            residual,
        )


def pca_from_data(
    data: np.ndarray,
    *,
    rank: int | None = None,
    mean: np.ndarray | None = None,
    noise_variance: float = 0.0,
    rtol: float = 1e-10,
) -> PCAPart:
    """Build a PCA part from samples by SVD of the centred data matrix.

    Parameters
    ----------
    data : (n, d) array
        One sample per row (``n`` may be far smaller than ``d``).
    rank : int, optional
        Keep at most this many components (default: all non-degenerate ones).
    mean : (d,) array, optional
        Use this mean instead of the sample mean.
    noise_variance : float
        Stored PPCA noise variance.
    rtol : float
        Components with singular value below ``rtol * s_max`` are dropped.

    Returns
    -------
    PCAPart
        Unbiased variances ``s^2 / (n - 1)``.
    """
    x = np.asarray(data, np.float64)
    if x.ndim != 2 or x.shape[0] < 2:
        raise InputError(f"need an (n >= 2, d) data matrix, got shape {x.shape}")
    mu = x.mean(0) if mean is None else np.asarray(mean, np.float64)
    u, s, vt = np.linalg.svd(x - mu, full_matrices=False)
    keep = s > rtol * (s[0] if s.size and s[0] > 0 else 1.0)
    if rank is not None:
        keep[rank:] = False
    basis = vt[keep].T
    variance = s[keep] ** 2 / (x.shape[0] - 1)
    return PCAPart(mu, basis, variance, noise_variance)
