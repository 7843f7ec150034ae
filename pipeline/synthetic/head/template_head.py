"""The procedural template head: meshing of :mod:`pipeline.synthetic.head.head_sdf`.

The field is sampled on a grid over the half space ``x >= 0`` whose spacing is
finer over the face than over the back of the head and the neck (a smooth warp
of a regular grid, see ``_warp``) and meshed by marching cubes; the ears, which
lie where the grid is coarse, are refined 1:4. The half mesh is mirrored
across ``x = 0`` sharing the vertices on that plane, so the symmetry map and the
triangulation are exactly symmetric by construction. Marching-cube stair steps
are then removed by tangential relaxation with re-projection onto the zero set
of the field, and the positions are re-symmetrised exactly.

Imports only :mod:`albedo_model.errors`, :mod:`pipeline.synthetic.head.head_sdf`,
:mod:`pipeline.synthetic.head.landmarks`, :mod:`pipeline.synthetic.head.regions` and third-party
packages.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from skimage.measure import marching_cubes

from albedo_model.errors import InputError
from pipeline.synthetic.head.head_sdf import HEAD_BOUNDS, Points, as_points, head_sdf
from pipeline.synthetic.head.landmarks import place_landmarks
from pipeline.synthetic.head.regions import region_masks

__all__ = ["TemplateHead", "build_template_head", "mirror_points", "DEFAULT_RESOLUTION"]

#: Grid spacing (mm) over the face. Away from the face the spacing grows by
#: up to ``_COARSE`` per axis, and behind the face (z < ``_WARP_Z[1]``) the x and y
#: spacings are further stretched by up to ``_BACK_STRETCH``.
DEFAULT_RESOLUTION = 2.4
_COARSE = 2.2
_BACK_STRETCH = 2.5
_FINE_X = (0.0, 52.0)
_FINE_Y = (-76.0, 64.0)
_FINE_Z0 = 60.0
_WARP_Z = (0.0, 55.0)
_RAMP = 25.0


@dataclasses.dataclass(frozen=True, eq=False)
class TemplateHead:
    """The template mesh with its symmetry map, landmarks and regions.

    Attributes
    ----------
    vertices : (n, 3) float64
        Model frame, mm (+x subject's left, +y up, +z out of the face).
    triangles : (m, 3) int32
        Counter-clockwise seen from outside.
    symmetry : (n,) int64
        ``vertices[symmetry[i]]`` is ``vertices[i]`` reflected across ``x = 0``;
        an involution. Midline vertices map to themselves.
    landmarks : dict of str to int
        Basel landmark name -> vertex index.
    regions : dict of str to (n,) bool
        ``eyeballs``, ``lips``, ``brows``, ``beard``, ``nose``, ``forehead``,
        ``cheeks``, ``ears``, ``skin`` (all but the eyeballs).
    """

    vertices: np.ndarray
    triangles: np.ndarray
    symmetry: np.ndarray
    landmarks: dict[str, int]
    regions: dict[str, np.ndarray]

    @property
    def n_vertices(self) -> int:
        """Number of vertices."""
        return int(self.vertices.shape[0])

    def landmark_points(self) -> dict[str, np.ndarray]:
        """Landmark name -> (3,) vertex position (mm)."""
        return {k: self.vertices[i].copy() for k, i in self.landmarks.items()}


def mirror_points(points: np.ndarray) -> np.ndarray:
    """Reflect (n, 3) points across the plane ``x = 0``."""
    out = np.array(points, np.float64, copy=True)
    out[:, 0] = -out[:, 0]
    return out


# -- grid -----------------------------------------------------------------------
# The field is sampled at W(u) for a regular grid u; W is a smooth diffeomorphism:
# z = Z(w), x = X(u) g(z), y = Y(v) g(z) with 1-D node tables X, Y, Z (fine over
# the face) and a stretch g(z) >= 1 that is 1 in front of the face. Marching
# cubes runs in u, and vertices are mapped through W (then projected onto the
# zero set, so the curvature of W does not matter).
def _axis(lo: float, hi: float, fine: tuple[float, float], h: float) -> np.ndarray:
    """Node coordinates from ``lo`` to past ``hi``, spacing ``h`` on ``fine`` growing outside."""
    out = [lo]
    t = lo
    while t < hi:
        dist = max(fine[0] - t, t - fine[1], 0.0)
        t = t + h * (1.0 + (_COARSE - 1.0) * min(dist / _RAMP, 1.0))
        out.append(t)
    return np.array(out)


def _stretch(z: np.ndarray) -> np.ndarray:
    t = np.clip((_WARP_Z[1] - z) / (_WARP_Z[1] - _WARP_Z[0]), 0.0, 1.0)
    return 1.0 + (_BACK_STRETCH - 1.0) * t * t * (3.0 - 2.0 * t)


def _grid(h: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    (_, y0, z0), (x1, y1, z1) = HEAD_BOUNDS
    return (
        _axis(0.0, x1, _FINE_X, h),
        _axis(y0, y1, _FINE_Y, h),
        _axis(z0, z1, (_FINE_Z0, z1), h),
    )


def _warp(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> Points:
    g = _stretch(z)
    return (x * g, y * g, z)


def _sample(xs: np.ndarray, ys: np.ndarray, zs: np.ndarray) -> np.ndarray:
    vol = np.empty((len(xs), len(ys), len(zs)))
    yy, zz = np.meshgrid(ys, zs, indexing="ij")
    y, z = yy.ravel(), zz.ravel()
    for i, x in enumerate(xs):
        vol[i] = head_sdf(_warp(np.full(len(y), x), y, z)).reshape(len(ys), len(zs))
    # a node exactly on the level would put a vertex on a grid node (and maybe on x = 0)
    vol[vol == 0.0] = 1e-9
    return vol


def _to_world(idx: np.ndarray, xs: np.ndarray, ys: np.ndarray, zs: np.ndarray) -> np.ndarray:
    def lin(i: np.ndarray, c: np.ndarray) -> np.ndarray:
        return np.interp(i, np.arange(len(c)), c)

    x, y, z = _warp(lin(idx[:, 0], xs), lin(idx[:, 1], ys), lin(idx[:, 2], zs))
    x[idx[:, 0] == 0.0] = 0.0
    return np.column_stack([x, y, z])


# -- half mesh -> symmetric mesh ------------------------------------------------------
def _mirror_weld(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mirror a half mesh (x >= 0) across x = 0, sharing the vertices with x == 0."""
    on_plane = v[:, 0] == 0.0
    f = f[~np.all(on_plane[f], axis=1)]
    used = np.zeros(len(v), bool)
    used[f.ravel()] = True
    keep = np.flatnonzero(used)
    remap = -np.ones(len(v), np.int64)
    remap[keep] = np.arange(len(keep))
    v, f, on_plane = v[keep], remap[f], on_plane[keep]
    n = len(v)
    off = np.flatnonzero(~on_plane)
    mirror_index = np.arange(n)
    mirror_index[off] = n + np.arange(len(off))
    verts = np.vstack([v, mirror_points(v[off])])
    tris = np.vstack([f, mirror_index[f][:, ::-1]])
    sym = np.arange(len(verts))
    sym[off] = n + np.arange(len(off))
    sym[n:] = off
    return verts, tris.astype(np.int32), sym.astype(np.int64)


def _refine(v: np.ndarray, f: np.ndarray, marked: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Red-green refinement: split the marked triangles 1:4, their neighbours conformingly.

    New vertices are edge midpoints (projected onto the surface later).
    """
    e = np.sort(np.stack([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]], 1), axis=2)  # (m, 3, 2)
    split = np.zeros(e.shape[:2], bool)
    split[marked] = True
    keys = e[..., 0] * len(v) + e[..., 1]
    split_keys = np.unique(keys[split])
    split = np.isin(keys, split_keys)
    mid_index = {int(k): len(v) + i for i, k in enumerate(split_keys)}
    a, b = split_keys // len(v), split_keys % len(v)
    v = np.vstack([v, 0.5 * (v[a] + v[b])])
    out = []
    for tri, sp, kk in zip(f, split, keys):
        n = int(sp.sum())
        if n == 0:
            out.append(tri)
            continue
        m = [mid_index.get(int(k), -1) for k in kk]  # midpoint of edge (i, i+1)
        i0, i1, i2 = (int(x) for x in tri)
        if n == 3:
            out += [(i0, m[0], m[2]), (m[0], i1, m[1]), (m[2], m[1], i2), (m[0], m[1], m[2])]
            continue
        r = int(np.argmax(sp)) if n == 1 else int(np.argmin(sp))
        c = (i0, i1, i2)[r:] + (i0, i1, i2)[:r]  # rotate so the special edge is (c0, c1)
        mm = m[r:] + m[:r]
        if n == 1:
            out += [(c[0], mm[0], c[2]), (mm[0], c[1], c[2])]
        else:  # edges (c1, c2) and (c2, c0) split, (c0, c1) not
            out += [(c[0], c[1], mm[1]), (c[0], mm[1], mm[2]), (mm[1], c[2], mm[2])]
    return v, np.array(out, np.int64)


def _symmetrize(v: np.ndarray, sym: np.ndarray) -> np.ndarray:
    out = 0.5 * (v + mirror_points(v[sym]))
    out[sym == np.arange(len(v)), 0] = 0.0
    return out


# -- clean-up ---------------------------------------------------------------------------
def _neighbour_mean(v: np.ndarray, edges: np.ndarray) -> np.ndarray:
    acc = np.zeros_like(v)
    cnt = np.bincount(edges[:, 0], minlength=len(v)).astype(float)
    for c in range(3):
        acc[:, c] = np.bincount(edges[:, 0], weights=v[edges[:, 1], c], minlength=len(v))
    return acc / np.maximum(cnt, 1.0)[:, None]


def _normals(v: np.ndarray, t: np.ndarray) -> np.ndarray:
    fn = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    acc = np.zeros_like(v)
    for j in range(3):
        for c in range(3):
            acc[:, c] += np.bincount(t[:, j], weights=fn[:, c], minlength=len(v))
    return acc / np.maximum(np.linalg.norm(acc, axis=1, keepdims=True), 1e-12)


def _project(v: np.ndarray, steps: int = 2) -> np.ndarray:
    """Newton steps onto the zero set of the field (forward-difference gradient)."""
    eps = 0.05
    for _ in range(steps):
        x, y, z = as_points(v)
        d = head_sdf((x, y, z))
        g = (
            np.column_stack(
                [
                    head_sdf((x + eps, y, z)) - d,
                    head_sdf((x, y + eps, z)) - d,
                    head_sdf((x, y, z + eps)) - d,
                ]
            )
            / eps
        )
        gg = np.maximum(np.einsum("ij,ij->i", g, g), 1e-6)
        step = (d / gg)[:, None] * g
        # a vertex far from the level (a poorly sampled crease) is only pulled a little
        n = np.linalg.norm(step, axis=1, keepdims=True)
        v = v - step * np.minimum(1.0, 1.0 / np.maximum(n, 1e-12))
    return v


def _relax(v: np.ndarray, t: np.ndarray, sym: np.ndarray, iterations: int) -> np.ndarray:
    edges = np.vstack([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    edges = np.unique(np.vstack([edges, edges[:, ::-1]]), axis=0)
    for _ in range(iterations):
        n = _normals(v, t)
        lap = _neighbour_mean(v, edges) - v
        lap -= np.einsum("ij,ij->i", lap, n)[:, None] * n
        v = _project(v + 0.6 * lap, steps=1)
        v = _symmetrize(v, sym)
    return v


def _in_ear_zone(v: np.ndarray) -> np.ndarray:
    """Where the grid is coarse but the ear needs detail (x >= 0 half)."""
    return (
        (v[:, 0] > 58.0)
        & (v[:, 1] > -32.0)
        & (v[:, 1] < 52.0)
        & (v[:, 2] > -30.0)
        & (v[:, 2] < 34.0)
    )


def build_template_head(*, resolution: float | None = None) -> TemplateHead:
    """Build the template head (deterministic: no randomness is involved).

    Parameters
    ----------
    resolution : float, optional
        Grid spacing over the face in mm (default :data:`DEFAULT_RESOLUTION`,
        about 19k vertices); the back of the head is meshed coarser.

    Returns
    -------
    TemplateHead

    Raises
    ------
    InputError
        If ``resolution`` is outside [0.5, 10] mm.
    """
    h = DEFAULT_RESOLUTION if resolution is None else float(resolution)
    if not 0.5 <= h <= 10.0:
        raise InputError(f"template resolution must be within [0.5, 10] mm, got {h}")
    xs, ys, zs = _grid(h)
    vol = _sample(xs, ys, zs)
    verts, faces, _, _ = marching_cubes(
        vol, level=0.0, gradient_direction="ascent", allow_degenerate=False
    )
    v = _to_world(verts, xs, ys, zs)
    faces = faces[:, ::-1].astype(np.int64)  # marching cubes winds them clockwise from outside
    v, faces = _refine(v, faces, np.all(_in_ear_zone(v)[faces], axis=1))
    v, t, sym = _mirror_weld(v, faces)
    v = _relax(v, t, sym, iterations=8)
    v = _symmetrize(v, sym)
    return TemplateHead(
        vertices=v,
        triangles=t,
        symmetry=sym,
        landmarks=place_landmarks(v, t, sym),
        regions=region_masks(v, t, sym),
    )
