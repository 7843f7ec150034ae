"""In-place BVH refit of an embreex scene, through ctypes on the bundled libembree4.

embreex 4.4.0.post1 exposes no geometry update, scene flags or build quality, so
a vertex change would otherwise mean a new scene (about 67 ms at 53k vertices,
mostly embreex's Python-level copy loop). In refit mode Embree only updates
the bounds of the existing BVH (about 1-2 ms, ``performance-notes.md`` §2).

The RTCScene handle is read from the Cython ``EmbreeScene`` object, whose layout
(``scene_i`` pointer at offset 16, ``is_committed`` int at 24, ``device`` object
at 32; ``EmbreeDevice.device`` at 16) is that of embreex 4.4.0.post1.
:func:`prepare_refit` checks that layout without dereferencing anything it has
not verified (object sizes, a round trip through ``is_committed``, the device
object's identity) and then asks Embree for the scene's device, which must be
the device the wrapper holds. Any mismatch raises :class:`RefitUnavailable`;
the caller (:mod:`albedo_model.render.raycast`, the only user) then falls back to
rebuilding scenes.

Notes
-----
Embree enum values used (embree4 headers): ``RTC_SCENE_FLAG_DYNAMIC = 1``,
``RTC_BUILD_QUALITY_LOW = 0``, ``RTC_BUILD_QUALITY_REFIT = 3``,
``RTC_BUFFER_TYPE_VERTEX = 1``. embreex stores vertices as ``RTC_FORMAT_FLOAT3``
with a 16-byte stride, i.e. a float32 (N, 4) array whose last column is padding.

This module imports nothing from the project, and not embreex either: it only
locates embreex's shared library.
"""

from __future__ import annotations

import ctypes
import glob
import importlib.util
import os
from collections.abc import Callable
from functools import lru_cache

import numpy as np

__all__ = ["RefitUnavailable", "RefitHandle", "prepare_refit", "verify_refit"]

_SCENE_FLAG_DYNAMIC = 1
_BUILD_QUALITY_LOW = 0
_BUILD_QUALITY_REFIT = 3
_BUFFER_TYPE_VERTEX = 1
_SCENE_BASICSIZE = 40
_DEVICE_BASICSIZE = 24
_OFF_SCENE_PTR, _OFF_COMMITTED, _OFF_DEVICE_OBJ = 16, 24, 32
_OFF_DEVICE_PTR = 16

_vp = ctypes.c_void_p


class RefitUnavailable(RuntimeError):
    """The in-place refit cannot be used safely with this embreex build."""


@lru_cache(maxsize=1)
def _library() -> ctypes.CDLL:
    spec = importlib.util.find_spec("embreex")
    if spec is None or not spec.submodule_search_locations:
        raise RefitUnavailable("embreex not found")
    pkg = list(spec.submodule_search_locations)[0]
    libs_dir = os.path.join(os.path.dirname(pkg), "embreex.libs")
    cands = sorted(glob.glob(os.path.join(libs_dir, "libembree4*.so*")))
    cands += sorted(glob.glob(os.path.join(libs_dir, "libembree4*.dylib")))
    cands += sorted(glob.glob(os.path.join(libs_dir, "embree4*.dll")))
    if not cands:
        raise RefitUnavailable(f"no bundled libembree4 in {libs_dir}")
    try:
        lib = ctypes.CDLL(cands[0])
        sig = {
            "rtcGetSceneDevice": (_vp, [_vp]),
            "rtcReleaseDevice": (None, [_vp]),
            "rtcGetDeviceError": (ctypes.c_int, [_vp]),
            "rtcGetSceneFlags": (ctypes.c_int, [_vp]),
            "rtcSetSceneFlags": (None, [_vp, ctypes.c_int]),
            "rtcSetSceneBuildQuality": (None, [_vp, ctypes.c_int]),
            "rtcGetGeometry": (_vp, [_vp, ctypes.c_uint]),
            "rtcSetGeometryBuildQuality": (None, [_vp, ctypes.c_int]),
            "rtcGetGeometryBufferData": (_vp, [_vp, ctypes.c_int, ctypes.c_uint]),
            "rtcUpdateGeometryBuffer": (None, [_vp, ctypes.c_int, ctypes.c_uint]),
            "rtcCommitGeometry": (None, [_vp]),
            "rtcCommitScene": (None, [_vp]),
        }
        for name, (res, args) in sig.items():
            fn = getattr(lib, name)
            fn.restype, fn.argtypes = res, args
    except (OSError, AttributeError) as exc:
        raise RefitUnavailable(f"cannot use {cands[0]}: {exc}") from exc
    return lib


def _read_ptr(address: int) -> int:
    return ctypes.c_void_p.from_address(address).value or 0


def _scene_handles(scene, device) -> tuple[int, int]:
    """(RTCScene, RTCDevice) of an embreex scene, after checking the object layout."""
    sizes = type(scene).__basicsize__, type(device).__basicsize__
    if sizes != (_SCENE_BASICSIZE, _DEVICE_BASICSIZE):
        raise RefitUnavailable("unexpected embreex object layout (sizes)")
    if _read_ptr(id(scene) + _OFF_DEVICE_OBJ) != id(device):
        raise RefitUnavailable("unexpected embreex object layout (device)")
    committed = ctypes.c_int.from_address(id(scene) + _OFF_COMMITTED)
    old = scene.is_committed
    try:
        for probe in (0x5A17, 0x0C0F):
            scene.is_committed = probe
            if committed.value != probe:
                raise RefitUnavailable("unexpected embreex object layout (is_committed)")
    finally:
        scene.is_committed = old
    scene_ptr = _read_ptr(id(scene) + _OFF_SCENE_PTR)
    device_ptr = _read_ptr(id(device) + _OFF_DEVICE_PTR)
    if not scene_ptr or not device_ptr:
        raise RefitUnavailable("null Embree handle")
    lib = _library()
    got = lib.rtcGetSceneDevice(scene_ptr)
    if got:
        lib.rtcReleaseDevice(got)  # rtcGetSceneDevice returns a new reference
    if got != device_ptr:
        raise RefitUnavailable("scene handle check failed")
    return scene_ptr, device_ptr


class RefitHandle:
    """Writable view of one scene's vertex buffer, and the calls that refit its BVH.

    Keep the owning ``EmbreeScene`` alive as long as this handle: the view points
    into memory Embree owns.
    """

    def __init__(self, scene_ptr: int, geom_ptr: int, device_ptr: int, vertices: np.ndarray):
        self._lib = _library()
        self._scene = scene_ptr
        self._geom = geom_ptr
        self._device = device_ptr
        self.vertices = vertices  # (N, 4) float32 view into Embree's buffer

    def _check(self, what: str) -> None:
        code = self._lib.rtcGetDeviceError(self._device)
        if code != 0:
            raise RefitUnavailable(f"Embree error {code} in {what}")

    def update(self, vertices: np.ndarray) -> None:
        """Write ``vertices`` (N, 3) into the buffer and refit the BVH (blocking)."""
        for c in range(3):  # per column: 5x faster than one (n, 3) -> (n, 4) strided copy
            np.copyto(self.vertices[:, c], vertices[:, c])
        lib = self._lib
        lib.rtcUpdateGeometryBuffer(self._geom, _BUFFER_TYPE_VERTEX, 0)
        lib.rtcCommitGeometry(self._geom)
        lib.rtcCommitScene(self._scene)
        self._check("refit")


def prepare_refit(scene, device, vertices: np.ndarray) -> RefitHandle:
    """Switch a not yet committed one-mesh embreex scene to refit mode and commit it.

    Parameters
    ----------
    scene : embreex.rtcore_scene.EmbreeScene
        Holding exactly one ``TriangleMesh`` (geometry id 0), not yet committed.
    device : embreex.rtcore.EmbreeDevice
        The device the scene was created with.
    vertices : (N, 3) float32
        The vertices the mesh was built from; the buffer must hold exactly these
        (checks the (N, 4) layout before the whole view is used).

    Returns
    -------
    RefitHandle

    Raises
    ------
    RefitUnavailable
        Whenever the layout or an Embree call is not as expected; the scene is
        then left uncommitted or committed unchanged, never half-modified.
    """
    lib = _library()
    if scene.is_committed:
        raise RefitUnavailable("scene already committed")
    scene_ptr, device_ptr = _scene_handles(scene, device)
    lib.rtcGetDeviceError(device_ptr)  # clear a stale error code
    geom = lib.rtcGetGeometry(scene_ptr, 0)
    if not geom:
        raise RefitUnavailable("no geometry 0")
    data = lib.rtcGetGeometryBufferData(geom, _BUFFER_TYPE_VERTEX, 0)
    if not data or lib.rtcGetDeviceError(device_ptr) != 0:
        raise RefitUnavailable("no vertex buffer")
    n = len(vertices)
    head = min(n, 4)
    probe = np.ctypeslib.as_array((ctypes.c_float * (4 * head)).from_address(data)).reshape(head, 4)
    if not np.array_equal(probe[:, :3], vertices[:head]):
        raise RefitUnavailable("unexpected vertex buffer layout")
    view = np.ctypeslib.as_array((ctypes.c_float * (4 * n)).from_address(data)).reshape(n, 4)
    if not np.array_equal(view[:, :3], vertices):
        raise RefitUnavailable("vertex buffer does not hold the mesh")
    flags = lib.rtcGetSceneFlags(scene_ptr)
    lib.rtcSetSceneFlags(scene_ptr, flags | _SCENE_FLAG_DYNAMIC)
    lib.rtcSetSceneBuildQuality(scene_ptr, _BUILD_QUALITY_LOW)
    lib.rtcSetGeometryBuildQuality(geom, _BUILD_QUALITY_REFIT)
    lib.rtcCommitGeometry(geom)
    lib.rtcCommitScene(scene_ptr)
    if lib.rtcGetDeviceError(device_ptr) != 0:
        raise RefitUnavailable("commit failed")
    scene.is_committed = 1
    return RefitHandle(scene_ptr, geom, device_ptr, view)


def _check_mesh(n: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """Make a closed UV sphere: (n*(n-1)+2, 3) vertices (poles shared), counter-clockwise."""
    th = np.linspace(0, np.pi, n + 1)[1:-1]
    ph = np.linspace(0, 2 * np.pi, n, endpoint=False)
    t, p = np.meshgrid(th, ph, indexing="ij")
    ring = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1).reshape(-1, 3)
    v = np.vstack([[0, 0, 1], ring, [0, 0, -1]])
    idx = 1 + np.arange(len(ring)).reshape(n - 1, n)
    nxt = np.roll(idx, -1, axis=1)
    top = np.stack([np.zeros(n, int), idx[0], nxt[0]], 1)
    bottom = np.stack([np.full(n, len(v) - 1), nxt[-1], idx[-1]], 1)
    a, b, c, d = idx[:-1], nxt[:-1], idx[1:], nxt[1:]
    quads = np.concatenate([np.stack([a, c, d], -1).reshape(-1, 3),
                            np.stack([a, d, b], -1).reshape(-1, 3)])
    return v, np.vstack([top, quads, bottom]).astype(np.int32)


def verify_refit(build: Callable[[np.ndarray, np.ndarray], tuple]) -> tuple[bool, str]:
    """Check on a small mesh that refitting gives exactly the hits of fresh builds.

    Parameters
    ----------
    build : callable
        ``build(vertices (N, 3) float32, triangles (M, 3) int32) -> (scene, device)``,
        a new, uncommitted embreex scene holding that mesh, and its device.

    Returns
    -------
    (ok, reason) : (bool, str)
        Never raises: any failure is reported as ``(False, reason)``.
    """
    try:
        v0, f = _check_mesh()
        rng = np.random.default_rng(0)
        g = np.linspace(-1.3, 1.3, 24)
        xy = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
        o = np.concatenate([xy, np.full((len(xy), 1), 5.0)], 1).astype(np.float32)
        d = np.array([[0.0, 0.0, -1.0]], np.float32)
        scene, device = build(v0.astype(np.float32), f)
        handle = prepare_refit(scene, device, v0.astype(np.float32))
        for k in range(3):
            v = v0 * (1.0 + 0.3 * k * rng.standard_normal((len(v0), 1)) / 3)
            v = (v + rng.normal(0, 0.2, 3)).astype(np.float32)
            handle.update(v)
            fresh, _ = build(v, f)
            a = scene.run(o, d, None, "INTERSECT", 1)
            b = fresh.run(o, d, None, "INTERSECT", 1)
            hit = b["primID"] >= 0
            if not np.array_equal(a["primID"], b["primID"]) or hit.sum() < 100:
                return False, "refit hits differ from a fresh build"
            for key in ("u", "v", "tfar"):
                if not np.allclose(a[key][hit], b[key][hit], atol=1e-5):
                    return False, f"refit {key} differs from a fresh build"
        return True, "refit verified"
    except RefitUnavailable as exc:
        return False, str(exc)
    except Exception as exc:  # never let a changed wheel crash the renderer
        return False, f"{type(exc).__name__}: {exc}"
