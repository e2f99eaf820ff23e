"""Fibers as Embree 4's native round linear curves, traced from Numba kernels with no Python between rays (issue 16,
first part: the geometry and the ray queries; the path tracer and the bake stages still trace tubes).

Why not embreex: it exposes triangle meshes only, copies its input element by element, and returns to Python per
batch of rays. The embreex wheel ships the Embree 4 library itself (``embreex.libs/libembree4*.so``), so this module
binds that library directly: ``ctypes`` for the few set-up calls (device, scene, geometry, buffers, commit) and
Numba ``ExternalFunction`` declarations for ``rtcIntersect1`` / ``rtcOccluded1``, resolved by symbol name (the
library is loaded with ``llvmlite.binding.load_library_permanently``), so kernels that call them stay cacheable.

Geometry and conventions
------------------------
* One ``RTC_GEOMETRY_TYPE_ROUND_LINEAR_CURVE`` (16) per ``FiberSet``: a vertex buffer of float32 (x, y, z, r) per
  fiber point (r the fiber's radius) and an index buffer holding the first vertex of each segment. Embree draws a
  segment as a cone between the two end spheres (Embree 4 manual, "RTC_GEOMETRY_TYPE_CURVE"): a fiber is a tube with
  round joints and round ends, exactly its swept sphere. Buffers are shared with Embree (no copy): the
  ``CurveScene`` keeps them alive.
* ``primID`` = the segment's index in ``CurveScene.segment_fiber`` / ``segment_start`` order (fiber by fiber,
  point by point); ``u`` ∈ [0, 1] the position along the segment.
* Lengths are the fibers' (centimetres for every preset), float32 inside Embree. ``Ng`` is Embree's unnormalised
  geometric normal (outward, not flipped toward the ray).

Ray buffer (``ray_buffer``): an RTCRayHit of 24 float32 words, 16-byte aligned inside a slightly larger array:
origin ``ORG`` (3), ``TNEAR``, direction ``DIR`` (3), ``TIME``, ``TFAR``, mask/id/flags (uint32 ``MASK``, ``ID``,
``FLAGS``), hit normal ``NG`` (3), ``U``, ``V``, ``PRIM``, ``GEOM``, ``INST`` (uint32). Each thread owns its own.
"""

from __future__ import annotations

import ctypes
import glob
import math
import os

import llvmlite.binding as llvm
import numba
import numpy as np
from numba import njit, prange, types

from knitbake.fibers.fiber_set import FiberSet

ROUND_LINEAR_CURVE = 16  # RTCGeometryType
BUFFER_INDEX, BUFFER_VERTEX = 0, 1  # RTCBufferType
FORMAT_UINT, FORMAT_FLOAT4 = 0x5001, 0x9004  # RTCFormat
INVALID_ID = 0xFFFFFFFF
# word offsets in the ray buffer (RTCRayHit: RTCRay then RTCHit)
ORG, TNEAR, DIR, TIME, TFAR, MASK, ID, FLAGS = 0, 3, 4, 7, 8, 9, 10, 11
NG, U, V, PRIM, GEOM, INST = 12, 15, 16, 17, 18, 19
RAY_WORDS = 24
ERRORS = {1: "unknown error", 2: "invalid argument", 3: "invalid operation", 4: "out of memory",
          5: "unsupported CPU", 6: "cancelled"}


def library_path() -> str:
    """The Embree 4 shared library that the embreex wheel ships."""
    import embreex

    found = sorted(glob.glob(os.path.join(os.path.dirname(embreex.__file__), os.pardir, "embreex.libs",
                                          "libembree4*.so*")))
    if not found:
        raise RuntimeError("the Embree 4 library of the embreex package was not found (embreex.libs/libembree4*.so)")
    return os.path.normpath(found[0])


_LIB_PATH = library_path()
llvm.load_library_permanently(_LIB_PATH)
_lib = ctypes.CDLL(_LIB_PATH)
_vp, _u32, _size = ctypes.c_void_p, ctypes.c_uint, ctypes.c_size_t
for _name, _res, _args in (("rtcNewDevice", _vp, [ctypes.c_char_p]), ("rtcReleaseDevice", None, [_vp]),
                           ("rtcGetDeviceError", ctypes.c_int, [_vp]), ("rtcNewScene", _vp, [_vp]),
                           ("rtcReleaseScene", None, [_vp]), ("rtcCommitScene", None, [_vp]),
                           ("rtcNewGeometry", _vp, [_vp, ctypes.c_int]), ("rtcReleaseGeometry", None, [_vp]),
                           ("rtcCommitGeometry", None, [_vp]), ("rtcAttachGeometry", _u32, [_vp, _vp]),
                           ("rtcSetSharedGeometryBuffer", None,
                            [_vp, ctypes.c_int, _u32, ctypes.c_int, _vp, _size, _size, _size])):
    getattr(_lib, _name).restype = _res
    getattr(_lib, _name).argtypes = _args

# pointers travel as intp (the x86-64 and aarch64 ABIs pass both in one integer register)
_rtc_intersect1 = types.ExternalFunction("rtcIntersect1", types.void(types.intp, types.intp, types.intp))
_rtc_occluded1 = types.ExternalFunction("rtcOccluded1", types.void(types.intp, types.intp, types.intp))


class CurveScene:
    """A committed Embree scene of a ``FiberSet``'s fibers as round linear curves (module docstring). ``handle`` is
    the scene pointer the kernels take; ``close()`` (or the garbage collector) releases it. ``threads``: Embree's
    build threads (default: Numba's thread count). ``commit=False`` copies the fibers into Embree's buffers and
    stops there, so that a caller can drop the ``FiberSet`` (24 B per point) before ``commit()`` builds the BVH,
    where the build's own peak is."""

    def __init__(self, fibers: FiberSet, threads: int | None = None, commit: bool = True):
        points = np.asarray(fibers.points, np.float64)
        offsets = np.asarray(fibers.offsets, np.int64)
        radius = np.asarray(fibers.radius, np.float64)
        n_fibers = len(offsets) - 1
        counts = np.diff(offsets)
        if points.ndim != 2 or points.shape[1] != 3 or offsets[0] != 0 or offsets[-1] != len(points):
            raise ValueError("fibers: points must be (P, 3) with offsets from 0 to P")
        if np.any(counts < 2):
            raise ValueError(f"fiber {int(np.argmax(counts < 2))} has fewer than 2 points")
        if not (np.all(np.isfinite(points)) and np.all(np.isfinite(radius)) and np.all(radius > 0)):
            raise ValueError("fibers: points and radii must be finite, radii > 0")
        if len(points) >= INVALID_ID:
            raise ValueError(f"{len(points)} fiber points: Embree indexes at most {INVALID_ID - 1}")
        self.vertices = np.empty((len(points), 4), np.float32)
        self.vertices[:, :3] = points
        self.vertices[:, 3] = np.repeat(radius, counts)
        first = np.ones(len(points), bool)
        first[offsets[1:] - 1] = False  # the last point of a fiber starts no segment
        self.segment_start = np.flatnonzero(first).astype(np.uint32)
        self.segment_fiber = np.repeat(np.arange(n_fibers, dtype=np.int32), counts - 1)
        threads = numba.get_num_threads() if threads is None else int(threads)
        self._device = _lib.rtcNewDevice(f"threads={threads}".encode())
        if not self._device:
            raise RuntimeError("Embree: cannot create a device")
        self._scene = None
        try:
            self._scene = _lib.rtcNewScene(self._device)
            geometry = _lib.rtcNewGeometry(self._device, ROUND_LINEAR_CURVE)
            _lib.rtcSetSharedGeometryBuffer(geometry, BUFFER_VERTEX, 0, FORMAT_FLOAT4, self.vertices.ctypes.data, 0,
                                            16, len(self.vertices))
            _lib.rtcSetSharedGeometryBuffer(geometry, BUFFER_INDEX, 0, FORMAT_UINT, self.segment_start.ctypes.data,
                                            0, 4, len(self.segment_start))
            _lib.rtcCommitGeometry(geometry)
            _lib.rtcAttachGeometry(self._scene, geometry)
            _lib.rtcReleaseGeometry(geometry)
        except BaseException:
            self.close()
            raise
        self.committed = False
        if commit:
            self.commit()

    def commit(self) -> None:
        """Build the BVH (once; later calls do nothing)."""
        if self.committed:
            return
        try:
            _lib.rtcCommitScene(self._scene)
            error = _lib.rtcGetDeviceError(self._device)
            if error:
                raise (MemoryError if error == 4 else RuntimeError)(
                    f"Embree: {ERRORS.get(error, error)} while building {len(self.segment_start)} fiber segments")
        except BaseException:
            self.close()
            raise
        self.committed = True

    @property
    def handle(self) -> int:
        if not self.committed:
            raise RuntimeError("CurveScene: commit() before tracing")
        return int(self._scene)

    @property
    def n_segments(self) -> int:
        return len(self.segment_start)

    def close(self) -> None:
        if getattr(self, "_scene", None):
            _lib.rtcReleaseScene(self._scene)
            self._scene = None
        if getattr(self, "_device", None):
            _lib.rtcReleaseDevice(self._device)
            self._device = None

    def __del__(self):
        self.close()


@njit(cache=True)
def ray_buffer():
    """A zeroed RTCRayHit of ``RAY_WORDS`` float32, 16-byte aligned (a view into a slightly larger array)."""
    raw = np.zeros(RAY_WORDS + 4, np.float32)
    shift = (-(raw.ctypes.data % 16) // 4) % 4
    return raw[shift:shift + RAY_WORDS]


@njit(cache=True)
def _set_ray(buf, ox, oy, oz, dx, dy, dz, tnear, tfar):
    buf[ORG], buf[ORG + 1], buf[ORG + 2], buf[TNEAR] = ox, oy, oz, tnear
    buf[DIR], buf[DIR + 1], buf[DIR + 2], buf[TIME], buf[TFAR] = dx, dy, dz, 0.0, tfar
    words = buf.view(np.uint32)
    words[MASK], words[ID], words[FLAGS] = INVALID_ID, 0, 0
    words[PRIM], words[GEOM], words[INST] = INVALID_ID, INVALID_ID, INVALID_ID


@njit(cache=True)
def intersect(scene, buf, ox, oy, oz, dx, dy, dz, tnear, tfar):
    """Closest hit along o + t d, t ∈ [tnear, tfar]: the segment index (primID) or −1 on a miss; ``buf`` then holds
    t (``TFAR``), the geometric normal (``NG``) and u (``U``)."""
    _set_ray(buf, ox, oy, oz, dx, dy, dz, tnear, tfar)
    _rtc_intersect1(scene, buf.ctypes.data, 0)
    words = buf.view(np.uint32)
    return -1 if words[GEOM] == INVALID_ID else np.int64(words[PRIM])


@njit(cache=True)
def occluded(scene, buf, ox, oy, oz, dx, dy, dz, tnear, tfar):
    """True when any fiber lies along o + t d for t ∈ [tnear, tfar] (Embree sets tfar to −inf then)."""
    _set_ray(buf, ox, oy, oz, dx, dy, dz, tnear, tfar)
    _rtc_occluded1(scene, buf.ctypes.data, 0)
    return buf[TFAR] == -np.inf


@njit(parallel=True, cache=True)
def _closest_batch(scene, origins, directions, tnear, t, prim, normal, u):
    for i in prange(origins.shape[0]):
        buf = ray_buffer()
        o, d = origins[i], directions[i]
        p = intersect(scene, buf, o[0], o[1], o[2], d[0], d[1], d[2], tnear, np.inf)
        prim[i] = p
        if p < 0:
            t[i] = np.inf
            normal[i, :] = 0.0
            u[i] = 0.0
            continue
        t[i] = buf[TFAR]
        n = math.sqrt(buf[NG] ** 2 + buf[NG + 1] ** 2 + buf[NG + 2] ** 2)
        for k in range(3):
            normal[i, k] = buf[NG + k] / n if n > 0.0 else 0.0
        u[i] = buf[U]


def closest_hits(scene: CurveScene, origins, directions, tnear: float = 0.0):
    """First hits of N rays (Python entry point for tests and tools): (t (N,), segment (N,) int64, unit normal (N, 3),
    u (N,)); misses have t = inf, segment = −1. Directions need not be unit: t is in units of |d|."""
    origins = np.ascontiguousarray(origins, np.float32).reshape(-1, 3)
    directions = np.ascontiguousarray(directions, np.float32).reshape(-1, 3)
    n = len(origins)
    t, prim, normal, u = np.empty(n), np.empty(n, np.int64), np.empty((n, 3)), np.empty(n)
    _closest_batch(scene.handle, origins, directions, float(tnear), t, prim, normal, u)
    return t, prim, normal, u


@njit(parallel=True, cache=True)
def _occluded_batch(scene, origins, directions, tfar, out):
    for i in prange(origins.shape[0]):
        buf = ray_buffer()
        o, d = origins[i], directions[i]
        out[i] = occluded(scene, buf, o[0], o[1], o[2], d[0], d[1], d[2], 0.0, tfar[i])


def any_hits(scene: CurveScene, origins, directions, tfar) -> np.ndarray:
    """Occlusion of N segments o + t d, t ∈ [0, tfar] (bool (N,))."""
    origins = np.ascontiguousarray(origins, np.float32).reshape(-1, 3)
    directions = np.ascontiguousarray(directions, np.float32).reshape(-1, 3)
    out = np.empty(len(origins), np.bool_)
    _occluded_batch(scene.handle, origins, directions, np.broadcast_to(np.asarray(tfar, np.float32),
                                                                        (len(origins),)).copy(), out)
    return out
