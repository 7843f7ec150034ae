"""Skin detail outside the span of smooth synthetic faces, and the projection floor it sets.

The synthetic subjects of :mod:`pipeline.synthetic.subjects` are smooth
fields, and a model of 60 of them reconstructs a 61st almost exactly. Real
faces are not like that: they carry freckles, moles, scars, stubble, make-up
and uneven tone that no small population spans. :func:`add_skin_detail`
puts such detail on a held-out subject's maps (each kind switchable through
:class:`SkinDetail`), and :func:`projection_floor` measures what the best
reconstruction by a model's albedo basis cannot reach (the floor under any
fit's error).

Every detail is a pure function of the maps, the template and a seed; it
darkens or tints the diffuse albedo multiplicatively (so the maps stay in
[0, 1]) and lowers the specular albedo where it changes the skin's surface
(stubble, make-up).

This module imports :mod:`albedo_model.errors`, :mod:`albedo_model.pca` and
:mod:`pipeline.synthetic.subjects` (the region weights).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from albedo_model.errors import InputError
from albedo_model.pca import PCAPart
from pipeline.synthetic.subjects import HeadTemplate, region_weights

__all__ = ["DETAIL_KINDS", "SkinDetail", "add_skin_detail", "projection_floor"]

#: The kinds of detail, in the order they are applied.
DETAIL_KINDS = ("uneven_tone", "freckles", "moles", "scars", "stubble", "makeup")

# melanin-like darkening: blue absorbed most (linear sRGB factor per unit strength)
_MELANIN_TINT = np.array([0.55, 0.75, 0.9])
_MOLE_COLOUR = np.array([0.06, 0.035, 0.022])
_SCAR_TINT = np.array([1.12, 0.97, 0.95])
_LIPSTICK = np.array([0.45, 0.06, 0.08])
_BLUSH_TINT = np.array([1.10, 0.90, 0.92])


class SkinDetail(NamedTuple):
    """Which detail a held-out subject gets (each kind switchable) and how strong.

    Attributes
    ----------
    freckles, moles, scars, stubble, makeup, uneven_tone : bool
        Each kind on (default) or off.
    strength : float
        Scales every kind's contrast (1 = the defaults below; 0 = no detail).
    """

    freckles: bool = True
    moles: bool = True
    scars: bool = True
    stubble: bool = True
    makeup: bool = True
    uneven_tone: bool = True
    strength: float = 1.0

    @classmethod
    def none(cls) -> SkinDetail:
        """Return the setting with every kind off."""
        return cls(*([False] * len(DETAIL_KINDS)), strength=0.0)

    def enabled(self) -> list[str]:
        """Return the names of the kinds switched on."""
        return [k for k in DETAIL_KINDS if getattr(self, k) and self.strength > 0]


def _spots(vertices: np.ndarray, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Soft disc weights in [0, 1]: max over spots of a Gaussian bump of each radius (mm)."""
    from scipy.spatial import cKDTree

    w = np.zeros(len(vertices))
    tree = cKDTree(vertices)
    for c, r in zip(centres, radii):
        idx = tree.query_ball_point(c, 2.5 * r)
        if idx:
            d2 = np.sum((vertices[idx] - c) ** 2, axis=1)
            w[idx] = np.maximum(w[idx], np.exp(-0.5 * d2 / (0.6 * r) ** 2))
    return w


def _pick(rng: np.random.Generator, weights: np.ndarray, k: int) -> np.ndarray:
    """``k`` vertex indices drawn with probability proportional to ``weights``."""
    p = np.clip(weights, 0.0, None)
    if p.sum() <= 0:
        return np.empty(0, int)
    return rng.choice(len(p), size=k, p=p / p.sum())


def _smooth_field(rng: np.random.Generator, vertices: np.ndarray, length_mm: float,
                  n_features: int = 96) -> np.ndarray:
    """Asymmetric smooth random field of unit variance (random Fourier features)."""
    freq = rng.standard_normal((3, n_features)) / length_mm
    arg = vertices @ freq + rng.uniform(0, 2 * np.pi, n_features)
    return np.sqrt(2.0 / n_features) * np.cos(arg) @ rng.standard_normal(n_features)


def add_skin_detail(diffuse: np.ndarray, specular: np.ndarray, template: HeadTemplate,
                    seed: int, detail: SkinDetail | None = None, *,
                    weights: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Return new diffuse and specular maps with the detail ``detail`` asks for.

    Parameters
    ----------
    diffuse, specular : (n, 3) float arrays, linear sRGB in [0, 1]
        A subject's maps (not modified).
    template : HeadTemplate
        Vertices (mm) and regions of the head the maps belong to.
    seed : int or sequence of int
        Every random choice derives from it.
    detail : SkinDetail, optional
        Default: every kind at strength 1.
    weights : dict, optional
        :func:`pipeline.synthetic.subjects.region_weights` of ``template`` (computed
        when omitted; pass it to detail many subjects).

    Returns
    -------
    diffuse, specular : (n, 3) float64 arrays in [0, 1]
    """
    detail = SkinDetail() if detail is None else detail
    d = np.array(diffuse, np.float64)
    s = np.array(specular, np.float64)
    v = np.asarray(template.vertices, np.float64)
    if d.shape != (len(v), 3) or s.shape != d.shape:
        raise InputError(f"maps must have shape ({len(v)}, 3), got {d.shape} and {s.shape}")
    a = float(detail.strength)
    if a <= 0 or not detail.enabled():
        return d, s
    w = region_weights(template) if weights is None else weights
    skin = np.clip(1.0 - w["eyeballs"] - 0.7 * w["lips"] - 0.6 * w["brows"], 0.0, 1.0)
    face = skin * np.clip(w["cheeks"] + w["nose"] + w["forehead"], 0.0, 1.0)
    root = np.random.SeedSequence(seed if np.ndim(seed) else [int(seed)])
    rngs = dict(zip(DETAIL_KINDS, (np.random.default_rng(s_) for s_ in root.spawn(6))))
    if detail.uneven_tone:  # blotchy asymmetric tone: +-12 % at 15 mm, darker in blue
        g = _smooth_field(rngs["uneven_tone"], v, 15.0)
        d *= np.exp(-0.12 * a * g[:, None] * _MELANIN_TINT / _MELANIN_TINT.mean()
                    * skin[:, None])
    if detail.freckles:  # 150-300 small spots over cheeks, nose, forehead
        rng = rngs["freckles"]
        idx = _pick(rng, face, int(rng.integers(150, 300)))
        spots = _spots(v, v[idx], rng.uniform(1.0, 2.2, len(idx))) * skin
        d *= 1.0 - 0.45 * a * spots[:, None] * _MELANIN_TINT
    if detail.moles:  # 3-6 dark brown moles of 1.5-3 mm
        rng = rngs["moles"]
        idx = _pick(rng, skin, int(rng.integers(3, 7)))
        m = np.clip(a * _spots(v, v[idx], rng.uniform(1.5, 3.0, len(idx))) * skin, 0, 1)
        d = (1 - m[:, None]) * d + m[:, None] * _MOLE_COLOUR
    if detail.scars:  # one pale, pinkish line of 20-40 mm, 1.5 mm wide
        rng = rngs["scars"]
        start = v[_pick(rng, face, 1)[0]]
        direction = rng.standard_normal(3)
        direction /= np.linalg.norm(direction)
        ts = np.linspace(0.0, rng.uniform(20.0, 40.0), 30)
        line = _spots(v, start + ts[:, None] * direction, np.full(len(ts), 1.5)) * skin
        d *= 1.0 + a * line[:, None] * (_SCAR_TINT - 1.0) * 2.0
        s *= 1.0 + 0.5 * a * line[:, None]
    if detail.stubble:  # per-vertex dark dots in the beard zone, lower gloss there
        rng = rngs["stubble"]
        zone = w["beard"] * (1 - w["lips"]) * rng.uniform(0.5, 1.0)
        dots = (rng.uniform(size=len(v)) < 0.35) * zone
        d *= 1.0 - 0.5 * a * dots[:, None] * _MELANIN_TINT
        s *= 1.0 - 0.4 * a * zone[:, None]
    if detail.makeup:  # lipstick, blush; make-up is matte
        rng = rngs["makeup"]
        lips = np.clip(w["lips"], 0, 1)[:, None] * a * rng.uniform(0.5, 0.9)
        d = (1 - lips) * d + lips * _LIPSTICK * rng.uniform(0.8, 1.2)
        blush = np.clip(w["cheeks"], 0, 1)[:, None] * a * rng.uniform(0.3, 0.8)
        d *= 1.0 + blush * (_BLUSH_TINT - 1.0)
        s *= 1.0 - 0.3 * blush
    return np.clip(d, 0.0, 1.0), np.clip(s, 0.0, 1.0)


def projection_floor(part: PCAPart, target: np.ndarray, rows: np.ndarray | None = None, *,
                     colour: str = "linear") -> float:
    """Mean squared error of the best least-squares reconstruction of ``target`` by ``part``.

    Parameters
    ----------
    part : PCAPart
        A colour part of dimension 3n (mean and basis).
    target : (n, 3) float array, linear sRGB
        The true map.
    rows : (n,) bool array, optional
        Vertices the error is taken over (and the least squares fitted on);
        default all.
    colour : {"linear", "srgb"}
        The part's colour space: for ``"srgb"`` the reconstruction is fitted to
        the encoded target and decoded before the error is taken.

    Returns
    -------
    float
        ``min_c mean((mu + W c - target)^2)`` over the rows and channels, the
        floor under the error of any estimate in the part's span.
    """
    t = np.asarray(target, np.float64).reshape(-1, 3)
    keep = np.ones(len(t), bool) if rows is None else np.asarray(rows, bool)
    sel = np.repeat(keep, 3)
    if colour == "srgb":
        from albedo_model.io.colour_space import decode_texture, encode_texture

        goal = encode_texture(np.clip(t, 0.0, 1.0)).reshape(-1)[sel]
    elif colour == "linear":
        goal = t.reshape(-1)[sel]
    else:
        raise InputError(f"colour must be 'linear' or 'srgb', got {colour!r}")
    mu = np.asarray(part.mean, np.float64)[sel]
    basis = np.asarray(part.basis, np.float64)[sel]
    coef, *_ = np.linalg.lstsq(basis, goal - mu, rcond=None)
    recon = mu + basis @ coef
    if colour == "srgb":
        recon = decode_texture(recon)
    return float(np.mean((recon - t.reshape(-1)[sel]) ** 2))
