"""Shape and expression variation on the template head, as PCA parts.

Shape
    A Gaussian process on the template surface: zero mean, a diagonal
    (per-axis independent) matrix kernel ``k(p, q) I`` whose scalar kernel is
    the sum of a linear term (head scale, ~3 % per axis), Gaussian terms of
    70, 35 and 18 mm length scale and windowed Gaussians that add detail to the
    nose, lips, chin, eyes/brows and ears. ``k`` is invariant under the mirror
    ``S = diag(-1, 1, 1)``, so the covariance splits into a mirror-symmetric
    and a mirror-antisymmetric part; the antisymmetric part is scaled down
    (faces are nearly symmetric). Each part is approximated by Nyström
    (inducing points by farthest-point sampling from a seeded start), rigid
    motions are projected out, and its principal directions are exact
    symmetric or antisymmetric fields. So the span of any truncation is closed
    under mirroring.

Expression
    Designed displacement fields at one standard deviation: ``jaw_open``
    (rotation of the mandible region about the jaw joint axis), ``smile``
    (mouth corners up, out and back, cheeks up) and ``brow_raise``,
    orthonormalised in that order.

Both use the interleaved layout ``x0 y0 z0 x1 ...`` in mm.

This module imports only :mod:`albedo_model`, :mod:`pipeline.synthetic.head.head_sdf` and
:mod:`pipeline.synthetic.head.template_head`.
"""

from __future__ import annotations

import numpy as np

from albedo_model.errors import InputError
from albedo_model.pca import PCAPart
from pipeline.synthetic.head.head_sdf import feature_sdfs
from pipeline.synthetic.head.template_head import TemplateHead

__all__ = ["EXPRESSION_MODES", "build_shape_model", "build_expression_model"]

#: Names of the expression components, in basis order.
EXPRESSION_MODES = ("jaw_open", "smile", "brow_raise")

_CENTER = np.array([0.0, 20.0, 10.0])
_LINEAR_STD = 0.03  # relative scale std per axis
_GAUSSIANS = ((70.0, 2.6), (35.0, 1.7), (18.0, 0.9))  # (length scale, std) mm
#: Windowed detail: (centre (left side), window radius, length scale, std), mm.
_LOCAL = (
    ((0.0, 2.0, 118.0), 24.0, 11.0, 2.2),  # nose
    ((0.0, -34.0, 108.0), 22.0, 10.0, 1.6),  # lips
    ((0.0, -64.0, 100.0), 22.0, 13.0, 2.2),  # chin
    ((30.0, 40.0, 95.0), 20.0, 10.0, 1.3),  # eyes and brows
    ((76.0, 10.0, 0.0), 28.0, 13.0, 2.5),  # ears
)
_ANTISYMMETRIC_VARIANCE = 0.12
_N_INDUCING = 420


# -- kernel --------------------------------------------------------------------------
def _window(p: np.ndarray, center, radius: float) -> np.ndarray:
    """Even (bilateral) smooth window, 1 at the centre(s)."""
    c = np.asarray(center, float)
    w = np.exp(-0.5 * np.sum((p - c) ** 2, axis=1) / radius**2)
    if c[0] != 0.0:
        cm = c * (-1.0, 1.0, 1.0)
        w = w + np.exp(-0.5 * np.sum((p - cm) ** 2, axis=1) / radius**2)
    return w


def _kernel(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Scalar kernel matrix (len(p), len(q)) in mm^2; invariant under the mirror."""
    pc, qc = p - _CENTER, q - _CENTER
    k = (_LINEAR_STD**2) * (pc @ qc.T)
    d2 = np.maximum(np.sum(p * p, 1)[:, None] + np.sum(q * q, 1)[None, :] - 2.0 * (p @ q.T), 0.0)
    for length, std in _GAUSSIANS:
        k += std**2 * np.exp(-0.5 / length**2 * d2)
    for center, radius, length, std in _LOCAL:
        wp, wq = _window(p, center, radius), _window(q, center, radius)
        ip, iq = np.flatnonzero(wp > 1e-7), np.flatnonzero(wq > 1e-7)  # the rest adds < 1e-13
        sub = np.ix_(ip, iq)
        k[sub] += std**2 * np.outer(wp[ip], wq[iq]) * np.exp(-0.5 / length**2 * d2[sub])
    return k


def _mirror_points(p: np.ndarray) -> np.ndarray:
    return p * np.array([-1.0, 1.0, 1.0])


def _farthest_points(p: np.ndarray, m: int, rng: np.random.Generator) -> np.ndarray:
    """Farthest-point sampling, twice as dense on the face and ears as elsewhere."""
    dense = 1.0 + _window(p, (0.0, 0.0, 100.0), 45.0) + _window(p, (76.0, 10.0, 0.0), 25.0)
    scale = np.minimum(dense, 2.0) ** 2
    chosen = [int(rng.integers(len(p)))]
    d2 = np.sum((p - p[chosen[0]]) ** 2, axis=1) * scale
    for _ in range(min(m, len(p)) - 1):
        i = int(np.argmax(d2))
        chosen.append(i)
        d2 = np.minimum(d2, np.sum((p - p[i]) ** 2, axis=1) * scale)
    return np.array(chosen)


def _parity_bases(
    template: TemplateHead, rng: np.random.Generator
) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Orthonormal eigenbases (n, r) and eigenvalues of the even (+1) and odd (-1) kernels.

    Computed on the half ``x >= 0`` and extended by parity, so every column is
    exactly even or odd under the symmetry map.
    """
    v, sym = template.vertices, template.symmetry
    n = len(v)
    half = np.flatnonzero(v[:, 0] >= 0.0)
    on_mid = sym[half] == half
    weight = np.where(on_mid, 1.0, 2.0)  # a half vertex stands for itself and its mirror
    z = v[half[_farthest_points(v[half], _N_INDUCING, rng)]]
    to_half = np.empty(n, np.int64)
    to_half[half] = np.arange(len(half))
    to_half[sym[half]] = np.arange(len(half))
    kzz, kzs = _kernel(z, z), _kernel(z, _mirror_points(z))
    kvz, kvs = _kernel(v[half], z), _kernel(v[half], _mirror_points(z))
    out = {}
    for parity in (1, -1):
        kzz_p = kzz + parity * kzs
        lam, u = np.linalg.eigh(0.5 * (kzz_p + kzz_p.T))
        keep = lam > 1e-9 * lam.max()
        phi_h = (kvz + parity * kvs) @ (u[:, keep] / np.sqrt(lam[keep]))
        if parity < 0:
            phi_h[on_mid] = 0.0
        gram = (phi_h * weight[:, None]).T @ phi_h
        d, q = np.linalg.eigh(0.5 * (gram + gram.T))
        order = np.argsort(d)[::-1]
        d, q = d[order], q[:, order]
        keep = d > 1e-9 * d[0]
        basis_h = phi_h @ (q[:, keep] / np.sqrt(d[keep]))
        sign = np.ones(n)
        if parity < 0:
            sign[v[:, 0] < 0.0] = -1.0
        out[parity] = (basis_h[to_half] * sign[:, None], d[keep] * 0.5)
    return out


def _rigid(v: np.ndarray) -> dict[int, np.ndarray]:
    """Orthonormal rigid-motion fields (3n, 3) by parity (+1 symmetric, -1 antisymmetric)."""
    n = len(v)
    c = v.mean(0)
    c[0] = 0.0
    r = v - c
    zero, one = np.zeros(n), np.ones(n)

    def field(x, y, z):
        return np.column_stack([x, y, z]).ravel()

    sym = [field(zero, one, zero), field(zero, zero, one), field(zero, -r[:, 2], r[:, 1])]
    anti = [field(one, zero, zero), field(r[:, 2], zero, -r[:, 0]), field(-r[:, 1], r[:, 0], zero)]
    return {1: np.linalg.qr(np.column_stack(sym))[0], -1: np.linalg.qr(np.column_stack(anti))[0]}


def build_shape_model(template: TemplateHead, *, rank: int = 40, seed: int = 0) -> PCAPart:
    """Low-rank Gaussian-process shape model on the template.

    Parameters
    ----------
    template : TemplateHead
    rank : int
        Number of principal components kept (symmetric and antisymmetric
        together, by decreasing variance).
    seed : int
        Seeds the start of the farthest-point choice of Nyström inducing points.

    Returns
    -------
    PCAPart
        ``mean`` = template vertices (3n,) interleaved, mm; ``basis`` (3n, rank)
        orthonormal, every column exactly mirror-symmetric or -antisymmetric
        (:func:`pipeline.modelling.symmetry.mirror_flat` of u is +-u); ``variance`` in mm^2,
        decreasing.
    """
    if rank < 1:
        raise InputError(f"shape model rank must be positive, got {rank}")
    rng = np.random.default_rng(seed)
    v = template.vertices
    n = len(v)
    scalar = _parity_bases(template, rng)
    rigid = _rigid(v)
    modes, variances = [], []
    # a symmetric field has an odd x and even y, z components; antisymmetric the reverse
    for parity, scale in ((1, 1.0), (-1, _ANTISYMMETRIC_VARIANCE)):
        # a symmetric field has an odd x and even y, z components; antisymmetric the reverse
        parities = [-parity, parity, parity]
        cand = sorted(
            ((lam_j, axis, j) for axis in range(3)
             for j, lam_j in enumerate(scalar[parities[axis]][1])),
            key=lambda c: -c[0],
        )[: rank + 30]  # fmt: skip
        # the candidate fields g (3n, K) are single-axis columns with orthogonal scalar
        # parts, so g^T g is diagonal; after projecting rigid motions R out it is
        # diag - (R^T g)^T (R^T g), and nothing of size 3n x K is ever formed
        lam = np.array([c[0] for c in cand]) * scale
        rig = rigid[parity].reshape(n, 3, -1)
        blocks = []
        rtg = np.zeros((rig.shape[2], len(cand)))
        for axis in range(3):
            cols = np.array([i for i, c in enumerate(cand) if c[1] == axis], np.int64)
            js = np.array([cand[i][2] for i in cols], np.int64)
            b_axis = scalar[parities[axis]][0][:, js] * np.sqrt(lam[cols])
            blocks.append((axis, cols, b_axis))
            rtg[:, cols] = rig[:, axis, :].T @ b_axis
        s2, w = np.linalg.eigh(np.diag(lam) - rtg.T @ rtg)
        top = np.argsort(s2)[::-1][:rank]
        m = w[:, top] / np.sqrt(s2[top])
        field = np.zeros((n, 3, len(top)))
        for axis, cols, b_axis in blocks:
            field[:, axis, :] = b_axis @ m[cols]
        field -= rig @ (rtg @ m)
        modes.append(field.reshape(3 * n, len(top)))
        variances.append(s2[top])
    basis = np.hstack(modes)
    var = np.concatenate(variances)
    order = np.argsort(var, kind="stable")[::-1][:rank]
    return PCAPart(v.reshape(-1).copy(), basis[:, order], var[order], 0.0)


# -- expressions ------------------------------------------------------------------------
def _smoothstep(t: np.ndarray) -> np.ndarray:
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _jaw_weight(v: np.ndarray, f: dict[str, np.ndarray]) -> np.ndarray:
    """1 on the mandible region (lower lip, chin, jaw), 0 above the mouth and behind the joint."""
    # away from the mouth: below the plane through the mouth corners and the jaw joint
    a = np.array([0.0, -34.0, 100.0])
    d = np.array([0.0, 36.0, -88.0])
    normal = np.array([0.0, -d[2], d[1]]) / np.hypot(d[1], d[2])  # up and forward
    below = _smoothstep(0.5 - ((v - a) @ normal) / 16.0)
    # at the mouth: a sharp split along the crease between the lips
    lips = _smoothstep(0.5 + (f["upper_lip"] - f["lower_lip"]) / 3.0)
    near_mouth = np.exp(-0.5 * (np.sum(((v - (0.0, -34.0, 105.0)) / (28.0, 9.0, 14.0)) ** 2, 1)))
    w = near_mouth * lips + (1.0 - near_mouth) * below
    w *= _smoothstep((v[:, 2] + 15.0) / 50.0)  # nothing behind the jaw joint
    # the lower neck stays; a long transition keeps the skin under the chin from folding
    w *= _smoothstep((v[:, 1] + 110.0) / 45.0)
    w[f["eyeballs"] < 1.0] = 0.0
    return w


def build_expression_model(template: TemplateHead) -> PCAPart:
    """Build a few designed expression modes as a zero-mean PCA part.

    Parameters
    ----------
    template : TemplateHead

    Returns
    -------
    PCAPart
        ``mean`` zeros (3n,); ``basis`` (3n, 3) orthonormal, columns in the order
        of :data:`EXPRESSION_MODES` (Gram-Schmidt, so component ``j`` is mode
        ``j`` minus its overlap with the earlier ones); ``variance`` is the
        squared size (mm^2) of each orthogonalised mode at one standard deviation:
        about 8 degrees of jaw rotation (~15 mm at the chin), a 4 mm smile and a
        4 mm brow raise.
    """
    v = template.vertices
    f = feature_sdfs(v)
    sx = np.sign(v[:, 0])

    theta = np.radians(8.0)
    joint = np.array([0.0, 2.0, 12.0])
    r = v - joint
    jaw = (
        _jaw_weight(v, f)[:, None] * theta * np.column_stack([np.zeros(len(v)), -r[:, 2], r[:, 1]])
    )

    corner = _window(v, (22.0, -34.0, 100.0), 9.0)
    cheek = _window(v, (36.0, -8.0, 90.0), 14.0)
    smile = corner[:, None] * np.column_stack(
        [2.5 * sx, np.full(len(v), 3.0), np.full(len(v), -1.5)]
    )
    smile += cheek[:, None] * np.array([0.0, 1.5, 1.0])

    brow = np.maximum(_window(v, (30.0, 51.0, 95.0), 14.0), _window(v, (0.0, 62.0, 104.0), 22.0))
    brow = np.minimum(brow, 1.0) * _smoothstep((v[:, 1] - 36.0) / 8.0)
    brow[f["eyeballs"] < 1.0] = 0.0
    raise_ = brow[:, None] * np.array([0.0, 4.0, 0.6])

    fields = np.column_stack([m.reshape(-1) for m in (jaw, smile, raise_)])
    q, rr = np.linalg.qr(fields)
    signs = np.sign(np.diag(rr))
    return PCAPart(np.zeros(3 * len(v)), q * signs, np.diag(rr) ** 2, 0.0)
