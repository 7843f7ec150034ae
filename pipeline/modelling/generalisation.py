"""Leave-one-out generalisation of the three specular model variants (paper Fig. "specgen").

For each subject ``i``: build the diffuse/specular models from the other
subjects (with symmetry augmentation, as the real model is built), then

* ``fit``: the generalisation error in the usual sense (Styner et al. 2003) --
  the held-out specular map is fitted by least squares with the first ``k``
  modes of the variant's specular part, and the residual is measured. This is
  what the paper's figure compares; its ordering "independent best,
  concatenated second, transferred worst" follows from PCA's optimality for the
  independent specular model;
* ``from_diffuse``: the specular map predicted from the diffuse map alone (the
  situation of a fit where specular is not observed separately): the first
  ``k`` coefficients are fitted to the held-out diffuse map and the specular
  part is evaluated at them. For ``independent`` the specular coefficients are
  unknown, so the prediction is the specular mean for every ``k``.

Error of a subject: root mean square over all vertices and channels (linear
sRGB). Results are averaged over subjects.

Imports only :mod:`albedo_model` and :mod:`pipeline.modelling.pca_variants`; matplotlib is
imported lazily by :func:`plot_specular_generalisation`.
"""

from __future__ import annotations

import os

import numpy as np

from albedo_model.errors import InputError
from albedo_model.io.atomic import atomic_path
from pipeline.modelling.pca_variants import VARIANTS, augment_with_mirror

__all__ = ["GramFold", "gram_eigenpairs", "plot_specular_generalisation",
           "specular_generalisation"]


_EIG_RTOL = 1e-12  # eigenvalues of a Gram matrix below this fraction of the largest are noise


def gram_eigenpairs(gram: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigenpairs of a PSD Gram matrix, largest first, numerically zero ones dropped.

    Also used by :mod:`pipeline.modelling.residual_variance`.
    """
    lam, u = np.linalg.eigh(gram)
    lam, u = lam[::-1], u[:, ::-1]
    keep = lam > _EIG_RTOL * max(lam[0], 0.0) if lam.size else lam > 0
    return lam[keep], u[:, keep]


def _nested_gains(coef: np.ndarray, gram: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Per-column reductions of squared residual of nested least-squares fits, (k,).

    Columns are ``X^T a_j`` for the columns ``a_j`` of ``coef`` (N, k), with
    ``gram = X X^T`` and ``xy = X y``. Gram-Schmidt in the metric ``gram``;
    a column (numerically) in the span of the earlier ones gains nothing.
    """
    n, k = coef.shape
    q = np.zeros((n, k))
    gains = np.zeros(k)
    for j in range(k):
        a = coef[:, j].copy()
        norm0 = a @ gram @ a
        if j:
            a -= q[:, :j] @ (q[:, :j].T @ (gram @ a))
        norm = a @ gram @ a
        if norm <= 1e-10 * max(norm0, 1e-300):
            continue
        q[:, j] = a / np.sqrt(norm)
        gains[j] = (q[:, j] @ xy) ** 2
    return gains


def _predictions(
    coef: np.ndarray, gram_d: np.ndarray, xy_d: np.ndarray, gram_s: np.ndarray,
    xy_s: np.ndarray, yy_s: float,
) -> np.ndarray:
    """Squared specular errors, coefficients fitted to diffuse with the first 0..k modes."""
    md = coef.T @ gram_d @ coef
    gd = coef.T @ xy_d
    ms = coef.T @ gram_s @ coef
    gs = coef.T @ xy_s
    out = np.empty(coef.shape[1] + 1)
    out[0] = yy_s
    for k in range(1, coef.shape[1] + 1):
        c = np.linalg.lstsq(md[:k, :k], gd[:k], rcond=1e-12)[0]
        out[k] = yy_s - 2 * c @ gs[:k] + c @ ms[:k, :k] @ c
    return np.maximum(out, 0.0)


def _curve(gains: np.ndarray, total: float, kmax: int) -> np.ndarray:
    """Squared residuals for 0..kmax modes from per-mode gains (padded if fewer modes)."""
    g = np.zeros(kmax)
    g[: min(kmax, len(gains))] = gains[:kmax]
    return np.maximum(total - np.concatenate([[0.0], np.cumsum(g)]), 0.0)


def _pad(errors: np.ndarray, kmax: int) -> np.ndarray:
    if len(errors) >= kmax + 1:
        return errors[: kmax + 1]
    return np.concatenate([errors, np.full(kmax + 1 - len(errors), errors[-1])])


class GramFold:
    """Centred Gram quantities of one leave-one-out split (training set T, held-out y).

    Parameters
    ----------
    gram : (N, N) array
        ``X X^T`` of all (augmented) samples, uncentred.
    train : (n,) int array
        Rows of the training set.
    held : int
        Row of the held-out sample ``y``.

    Attributes
    ----------
    gram : (n, n) array
        ``X_c X_c^T`` of the training rows centred on their mean.
    xy : (n,) array
        ``X_c (y - mean_T)``.
    yy : float
        ``|y - mean_T|^2``.
    """

    def __init__(self, gram: np.ndarray, train: np.ndarray, held: int) -> None:
        n = len(train)
        g_tt = gram[np.ix_(train, train)]
        g_ty = gram[train, held]
        row = g_tt.mean(axis=1)
        centre = np.eye(n) - 1.0 / n
        self.gram = centre @ g_tt @ centre               # X X^T
        self.xy = centre @ (g_ty - row)                  # X (y - mean)
        self.yy = gram[held, held] - 2 * g_ty.mean() + g_tt.mean()   # |y - mean|^2


def specular_generalisation(
    diffuse: np.ndarray,
    specular: np.ndarray,
    symmetry: np.ndarray | None,
    *,
    variants: tuple[str, ...] = VARIANTS,
    max_components: int | None = None,
) -> dict:
    """Leave-one-out specular generalisation error of the model variants.

    Parameters
    ----------
    diffuse, specular : (S, n, 3) arrays
        Ground-truth albedo of S >= 3 subjects, linear sRGB.
    symmetry : (n,) int array or None
        Symmetry map for augmentation (``None``: no augmentation).
    variants : tuple of str
        Any of ``"independent", "concatenated", "transferred"``.
    max_components : int, optional
        Largest number of modes evaluated (default: all a training set allows).

    Returns
    -------
    dict
        ``components``: (K + 1,) ints 0..K; ``fit`` and ``from_diffuse``: dicts
        variant -> (S, K + 1) per-subject RMS errors; ``fit_mean`` and
        ``from_diffuse_mean``: variant -> (K + 1,) means over subjects;
        ``n_subjects``, ``n_vertices``, ``augmented``.

    Notes
    -----
    Every mode of every variant is a linear combination of training samples,
    so the computation runs on Gram matrices of the (augmented) samples: one
    pass over the data, then (2S)^3 work per split. It equals building each
    split's models with :func:`pipeline.modelling.pca_variants.build_albedo_parts`
    and fitting in vertex space (checked in the tests).
    """
    d = np.asarray(diffuse, np.float64)
    s = np.asarray(specular, np.float64)
    if d.ndim != 3 or d.shape != s.shape or d.shape[2] != 3:
        raise InputError(
            f"need diffuse and specular maps of equal shape (S, n, 3), got {d.shape}, {s.shape}"
        )
    n_sub, n_vert = d.shape[:2]
    if n_sub < 3:
        raise InputError(f"leave-one-out needs at least 3 subjects, got {n_sub}")
    unknown = set(variants) - set(VARIANTS)
    if unknown:
        raise InputError(f"unknown variants {sorted(unknown)}")
    copies = 1
    if symmetry is not None:
        d, s = augment_with_mirror(d, symmetry), augment_with_mirror(s, symmetry)
        copies = 2
    xd = d.reshape(len(d), -1)
    xs = s.reshape(len(s), -1)
    gram_d, gram_s = xd @ xd.T, xs @ xs.T
    kmax_all = (n_sub - 1) * copies - 1
    kmax = kmax_all if max_components is None else max(0, min(max_components, kmax_all))
    dim = 3 * n_vert

    fit = {v: np.empty((n_sub, kmax + 1)) for v in variants}
    pred = {v: np.empty((n_sub, kmax + 1)) for v in variants}
    for i in range(n_sub):
        train = np.array([j for j in range(len(d)) if j % n_sub != i])
        fd, fs = GramFold(gram_d, train, i), GramFold(gram_s, train, i)
        for v in variants:
            if v == "independent":
                lam, u = gram_eigenpairs(fs.gram)
                gains = (u.T @ fs.xy) ** 2 / lam
                fit[v][i] = np.sqrt(_curve(gains, fs.yy, kmax) / dim)
                pred[v][i] = np.sqrt(fs.yy / dim)
                continue
            _, u = gram_eigenpairs(fd.gram + fs.gram if v == "concatenated" else fd.gram)
            u = u[:, :kmax]
            fit[v][i] = np.sqrt(_curve(_nested_gains(u, fs.gram, fs.xy), fs.yy, kmax) / dim)
            err = _predictions(u, fd.gram, fd.xy, fs.gram, fs.xy, fs.yy)
            pred[v][i] = np.sqrt(_pad(err, kmax) / dim)
    return {
        "components": np.arange(kmax + 1),
        "fit": fit,
        "from_diffuse": pred,
        "fit_mean": {v: e.mean(axis=0) for v, e in fit.items()},
        "from_diffuse_mean": {v: e.mean(axis=0) for v, e in pred.items()},
        "n_subjects": n_sub,
        "n_vertices": n_vert,
        "augmented": symmetry is not None,
    }


def plot_specular_generalisation(result: dict, path: str | os.PathLike) -> None:
    """Plot the leave-one-out curves of :func:`specular_generalisation` to an image file.

    Left panel: generalisation (least-squares fit of the held-out specular map).
    Right panel: specular predicted from the held-out diffuse map. Mean over
    subjects with a band of one standard error. Written atomically.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    k = result["components"]
    n = result["n_subjects"]
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=False)
    titles = {
        "fit": "Generalisation (specular fitted)",
        "from_diffuse": "Specular predicted from diffuse",
    }
    for ax, key in zip(axes, ("fit", "from_diffuse")):
        for v, err in result[key].items():
            mean = err.mean(axis=0)
            se = err.std(axis=0, ddof=1) / np.sqrt(n) if n > 1 else np.zeros_like(mean)
            ax.plot(k, mean, label=v)
            ax.fill_between(k, mean - se, mean + se, alpha=0.2)
        ax.set_xlabel("number of components")
        ax.set_title(titles[key], fontsize=10)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("RMS specular albedo error (linear sRGB)")
    axes[0].legend()
    aug = "with symmetry augmentation" if result.get("augmented") else "no augmentation"
    fig.suptitle(f"Leave-one-out, {n} synthetic subjects, {aug}", fontsize=10)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120)
    plt.close(fig)
