"""Embree ray casting of the model mesh: primary hits, occlusion, visibility.

The renderer casts one ray per pixel in the **model frame** (see
:func:`albedo_model.camera.camera_rays`), so pose and camera changes never touch
the BVH; shape/expression changes refit the BVH in place
(:mod:`albedo_model.render.embree_refit`), with a verified fallback to a rebuild.

Back faces: Embree reports the nearest hit of either side. scalismo's
rasteriser culls triangles with ``n . (a - eye) > 0`` (``n = (b-a) x (c-a)``),
which for a hit on a ray with direction ``d`` is ``n . d > 0``. :meth:`RayCaster.cast`
matches it (``cull_backfaces=True``): rays whose nearest hit is back-facing are
continued just behind that hit until they reach a front face or leave the mesh.
On closed meshes seen from outside no ray needs this, so the cost is one dot
product per ray; open meshes seen from behind (a face mask in profile) pay for
the few re-cast rays only.

Robustness: Embree's default (robust) traversal is watertight but about 20 %
slower. Without it, about one ray in 10^5 (more when rays run exactly along
mesh edges, e.g. in a symmetry plane) slips through a shared edge. The casters
here default to the fast mode and close those leaks where it matters: pixel
grids (``cast(..., image_shape=(H, W))`` re-casts isolated misses) and point
visibility (:func:`visible_points` uses three slightly tilted rays). Tests
check both against robust traversal and a z-buffer reference.
:mod:`albedo_model.render.scene_slots` double-buffers two casters for MCMC proposals.

This module owns the Embree device, scenes and queries (and the threads they
run on); the array work around the queries (ray buffers, hit records, windows,
leak closing, back-face continuation, visibility rays) is in
:mod:`albedo_model.render.ray_batches`.

This is the only module that imports ``embreex``. It imports
:mod:`albedo_model.render.embree_refit`, :mod:`albedo_model.render.ray_batches`
and :mod:`albedo_model.errors`.
"""

from __future__ import annotations

import logging
import os
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from embreex import mesh_construction, rtcore, rtcore_scene

from albedo_model.errors import InputError
from albedo_model.render.embree_refit import (
    RefitHandle, RefitUnavailable, prepare_refit, verify_refit,
)
from albedo_model.render.ray_batches import (
    RayHits, as_rays, bounds_scale, cast_window, checked_mesh, checked_vertices, close_leaks,
    continue_past_backfaces, grid_window, ray_pair, vertex_bounds, visibility_rays,
)

__all__ = ["RayHits", "RayCaster", "visible_points", "embree_pass", "refit_check",
           "default_threads"]

log = logging.getLogger(__name__)

_MIN_SPLIT = 2048  # below this many rays a second thread costs more than it saves
_lock = threading.Lock()
_state: dict = {}


def default_threads() -> int:
    """min(2, usable CPUs); CPU affinity (taskset) is respected where the OS reports it."""
    try:
        n = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        n = os.cpu_count() or 1
    return max(1, min(2, n))


def _device() -> rtcore.EmbreeDevice:
    with _lock:
        if "device" not in _state:
            _state["device"] = rtcore.EmbreeDevice()
        return _state["device"]


def _executor() -> ThreadPoolExecutor:
    with _lock:
        if "pool" not in _state:
            _state["pool"] = ThreadPoolExecutor(max_workers=1, thread_name_prefix="raycast")
        return _state["pool"]


class RayCaster:
    """Embree scene of one triangle mesh, with in-place vertex updates.

    Parameters
    ----------
    vertices : (n, 3) float array, model frame
    triangles : (m, 3) int array, counter-clockwise seen from outside
    threads : {1, 2}, optional
        Rays are split in halves over two threads (Embree releases the GIL).
        Default :func:`default_threads`.
    robust : bool
        Embree's robust (watertight) traversal. The default False is about 20 %
        faster; see the module notes for how its rare edge leaks are closed.
    update : {"auto", "refit", "rebuild"}
        How :meth:`update_vertices` works. "auto" refits when
        :func:`refit_check` passed in this process, else rebuilds; "refit" is
        the same but logs a warning when refitting is unavailable.

    Attributes
    ----------
    refit_supported : bool
        True when vertex updates refit the BVH in place.
    update_method : str
        "refit" or "rebuild".
    """

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray, *,
                 threads: int | None = None, robust: bool = False, update: str = "auto"):
        v, tri = checked_mesh(vertices, triangles)
        if update not in ("auto", "refit", "rebuild"):
            raise InputError(f"update must be 'auto', 'refit' or 'rebuild', got {update!r}")
        self.threads = default_threads() if threads is None else int(threads)
        if self.threads not in (1, 2):
            raise InputError(f"threads must be 1 or 2, got {threads}")
        self.robust = bool(robust)
        self._triangles = tri
        self._n_vertices = len(v)
        self._bounds = vertex_bounds(v)
        want_refit = update != "rebuild"
        ok, reason = refit_check() if want_refit else (False, "rebuild requested")
        if want_refit and not ok and update == "refit":
            log.warning("BVH refit unavailable (%s); rebuilding scenes instead", reason)
        self._refit: RefitHandle | None = None
        self._build(v, refit=want_refit and ok)
        self.scale = bounds_scale(self._bounds)

    @property
    def refit_supported(self) -> bool:
        """True when vertex updates refit the BVH in place."""
        return self._refit is not None

    @property
    def update_method(self) -> str:
        """How :meth:`update_vertices` works: "refit" or "rebuild"."""
        return "refit" if self._refit is not None else "rebuild"

    @property
    def n_vertices(self) -> int:
        """Number of vertices, fixed at construction."""
        return self._n_vertices

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) float64: min and max corner of the current vertices (read-only)."""
        return self._bounds

    @property
    def triangles(self) -> np.ndarray:
        """(m, 3) int32 triangle indices (read-only view)."""
        t = self._triangles.view()
        t.flags.writeable = False
        return t

    def _build(self, v: np.ndarray, *, refit: bool) -> None:
        device = _device()
        scene = rtcore_scene.EmbreeScene(device, robust=self.robust)
        mesh_construction.TriangleMesh(scene, v, self._triangles)
        handle = None
        if refit:
            try:
                handle = prepare_refit(scene, device, v)
            except RefitUnavailable as exc:
                log.info("BVH refit unavailable for this scene (%s); rebuilding instead", exc)
        if handle is None and not scene.is_committed:
            # embreex commits lazily on the first query; do it now, single-threaded
            scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32))
        self._scene, self._refit = scene, handle

    def update_vertices(self, vertices: np.ndarray) -> None:
        """Move the vertices (same topology): in-place BVH refit, or a rebuild.

        Parameters
        ----------
        vertices : (n, 3) float array, model frame, same n as at construction
        """
        v = checked_vertices(vertices, self._n_vertices)
        self._bounds = vertex_bounds(v)
        if self._refit is not None:
            try:
                self._refit.update(v)
                return
            except RefitUnavailable as exc:
                log.info("BVH refit failed (%s); rebuilding from now on", exc)
                self._refit = None
        self._build(v, refit=False)

    def _occluded_run(self, o, d, tmax):
        return self._scene.run(o, d, tmax, "OCCLUDED", None)

    def _split_run(self, fn, o, d, tfar, *extra) -> list:
        """``fn(o, d, tfar, *extra)`` on the rays, in two halves on two threads when worth it.

        ``extra`` are per-ray output arrays, split like the rays.
        """
        p = len(o)
        if self.threads == 1 or p < _MIN_SPLIT:
            return [fn(o, d, tfar, *extra)]
        h = p // 2
        d1, d2 = (d, d) if len(d) == 1 else (d[:h], d[h:])
        t1, t2 = (tfar, tfar) if tfar is None or np.isscalar(tfar) else (tfar[:h], tfar[h:])
        fut = _executor().submit(fn, o[:h], d1, t1, *(x[:h] for x in extra))
        second = fn(o[h:], d2, t2, *(x[h:] for x in extra))
        return [fut.result(), second]

    def _intersect_into(self, o, d, tfar, prim, bary, t, back) -> None:
        """Nearest hits of either side written into the output slices (misses: -1, 0, inf)."""
        r = self._scene.run(o, d, tfar, "INTERSECT", 1)
        prim[:] = r["primID"]
        hit = prim >= 0
        np.copyto(bary[:, 0], r["u"])
        np.copyto(bary[:, 1], r["v"])
        np.copyto(t, r["tfar"])
        if not hit.all():
            miss = ~hit  # (np.copyto with where= is ~6x faster than boolean-index assignment)
            np.copyto(bary[:, 0], 0.0, where=miss)
            np.copyto(bary[:, 1], 0.0, where=miss)
            np.copyto(t, np.inf, where=miss)
        # back-facing hit: geometric normal (b-a) x (c-a) along the ray
        ng = r["Ng"]
        if len(d) == len(o):
            dot = ng[:, 0] * d[:, 0]
            dot += ng[:, 1] * d[:, 1]
            dot += ng[:, 2] * d[:, 2]
        else:
            dot = ng @ d[0]
        np.greater(dot, 0, out=back)
        back &= hit

    def _intersect(self, o, d, tfar):
        """(prim, bary, t, back) of the nearest hits of either side (misses: -1, 0, inf)."""
        p = len(o)
        prim = np.empty(p, np.int32)
        bary = np.empty((p, 2), np.float32)
        t = np.empty(p, np.float32)
        back = np.empty(p, bool)
        self._split_run(self._intersect_into, o, d, tfar, prim, bary, t, back)
        return prim, bary, t, back

    def cast(self, origins: np.ndarray, directions: np.ndarray, *,
             tfar: float | None = None, cull_backfaces: bool = True,
             image_shape: tuple[int, int] | None = None,
             window: tuple[int, int, int, int] | None = None) -> RayHits:
        """Nearest hits of a batch of rays.

        Parameters
        ----------
        origins : (P, 3) float32, model frame
        directions : (P, 3) or (1, 3) float32, model frame (need not be unit)
        tfar : float, optional
            Largest ray parameter (the far plane); default unlimited.
        cull_backfaces : bool
            Skip back-facing hits as scalismo's rasteriser does (see module notes).
        image_shape : (H, W), optional
            The rays form a row-major pixel grid (as from
            :func:`albedo_model.camera.camera_rays`). Without robust traversal,
            Embree lets about one ray in 10^5 slip through a shared edge; with
            the grid known, every miss between two hits (horizontally or
            vertically) is re-cast 1/1000 pixel towards a neighbour, which
            closes these leaks and leaves true gaps missing.
        window : (y0, y1, x0, x1), optional
            With ``image_shape``: cast only the rays of these rows and columns
            and report the others as misses (e.g. outside
            :func:`albedo_model.camera.pixel_window`, where nothing can be hit).

        Returns
        -------
        RayHits
        """
        o, d = ray_pair(origins, directions)
        win = grid_window(len(o), image_shape, window)
        if win is not None:  # (see ray_batches.cast_window)
            def cast_sub(oo, dd, shape):
                return self.cast(oo, dd, tfar=tfar, cull_backfaces=cull_backfaces,
                                 image_shape=shape)

            return cast_window(cast_sub, o, d, image_shape, win)
        limit = None if tfar is None else float(tfar)
        prim, bary, t, back = self._intersect(o, d, limit)
        if cull_backfaces and back.any():
            continue_past_backfaces(self._intersect, o, d, limit, prim, bary, t,
                                    np.flatnonzero(back), self.scale)
        if image_shape is not None and not self.robust:
            def cast_shifted(oo, dd):
                return self.cast(oo, dd, tfar=limit, cull_backfaces=cull_backfaces)

            close_leaks(cast_shifted, o, d, prim, bary, t, image_shape)
        return RayHits(prim, bary, t)

    def occluded(self, origins: np.ndarray, directions: np.ndarray,
                 tmax: float | np.ndarray | None = None) -> np.ndarray:
        """Whether anything (either side of any triangle) lies on each ray segment.

        Parameters
        ----------
        origins : (P, 3) float32, model frame
        directions : (P, 3) or (1, 3) float32, model frame
        tmax : float or (P,) float array, optional
            Segment end in units of the direction length; default unlimited.

        Returns
        -------
        (P,) bool
        """
        o, d = ray_pair(origins, directions)
        if tmax is not None and not np.isscalar(tmax):
            tmax = np.ascontiguousarray(tmax, dtype=np.float32).reshape(-1)
            if len(tmax) != len(o):
                raise InputError(f"tmax must have {len(o)} entries, got {len(tmax)}")
            tmax = tmax.copy()  # embreex may write into it
        elif tmax is not None:
            tmax = float(tmax)
        parts = self._split_run(self._occluded_run, o, d, tmax)
        ids = parts[0] if len(parts) == 1 else np.concatenate(parts)
        return np.asarray(ids) >= 0


def embree_pass(caster: RayCaster, origins: np.ndarray, directions: np.ndarray,
                tfar: float | None = None) -> dict:
    """One bare Embree query of ``caster``'s scene on the calling thread (for benchmarks).

    The nearest hits of either side as embreex returns them (a dict of ``primID``,
    ``u``, ``v``, ``tfar``, ``Ng``, ...): :meth:`RayCaster.cast` is this plus its
    bookkeeping (back-face test, leak closing, output arrays).
    """
    o = as_rays(origins, "origins")
    d = as_rays(directions, "directions")
    return caster._scene.run(o, d, None if tfar is None else float(tfar), "INTERSECT", 1)


def visible_points(points_model: np.ndarray, eye_model: np.ndarray | None, caster: RayCaster,
                   eps: float | None = None, *, direction: np.ndarray | None = None) -> np.ndarray:
    """Whether each point has a free line of sight to the camera.

    Parameters
    ----------
    points_model : (n, 3) float array, model frame (typically on the surface)
    eye_model : (3,) float array or None
        Camera centre in the model frame (:func:`albedo_model.camera.eye_position_model`).
    caster : RayCaster
    eps : float, optional
        Offset of the ray start along the ray, in model units, so that a point's
        own triangle does not occlude it; default ``1e-4 * caster.scale``.
    direction : (3,) float array, optional
        For orthographic cameras (``eye_model=None``): the model-frame direction
        towards the camera (:func:`albedo_model.camera.towards_camera_model`).

    Returns
    -------
    (n,) bool

    Notes
    -----
    Each point is tested with three rays (the direct one and two tilted by
    1e-5 rad) and counts as occluded if any is blocked. Only
    occlusion is tested; a point on a surface facing away from the camera
    is reported visible when nothing else is in the way (on closed meshes its
    own mesh is). For directional-light shadows use :meth:`RayCaster.occluded`.
    """
    eps = 1e-4 * caster.scale if eps is None else float(eps)
    origins, dirs, tmax = visibility_rays(points_model, eye_model, eps, direction)
    occ = caster.occluded(origins, dirs, tmax)
    return ~occ.reshape(3, -1).any(axis=0)


def refit_check() -> tuple[bool, str]:
    """Verify once per process that an in-place refit gives the hits of a fresh build.

    Returns
    -------
    (ok, reason) : (bool, str), cached for the process.
    """
    with _lock:
        if "refit" in _state:
            return _state["refit"]

    def build(vertices: np.ndarray, triangles: np.ndarray):
        dev = _device()
        scene = rtcore_scene.EmbreeScene(dev, robust=False)
        mesh_construction.TriangleMesh(scene, vertices, triangles)
        return scene, dev

    result = verify_refit(build)
    with _lock:
        _state.setdefault("refit", result)
        if not result[0]:
            log.info("BVH refit disabled: %s", result[1])
        return _state["refit"]
