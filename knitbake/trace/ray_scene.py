"""Ray casting against a TubeMesh with Embree (``embreex``), for the offline baker.

Conventions
-----------
* Lengths are those of the mesh (centimetres for every preset). Embree works in float32; inputs are validated and
  normalised in float64, then cast.
* Directions need not be unit: they are normalised, and ``t`` is the Euclidean distance from the ray origin.
* embreex fixes Embree's ``tnear`` at 0, so every ray starts at ``origin + eps * direction`` instead, and the
  returned distances add ``eps`` back: hits closer than ``eps`` to the origin are ignored, so a ray leaving a
  surface does not hit it again. Default ``eps = EPS_REL * extent`` with ``extent`` the larger of the bounding-box
  diagonal and the largest absolute coordinate: float32 rounding of a hit point is about ``6e-8 * extent``, which
  the default clears over 100 times, while staying near 1 % of a fiber radius for one yarn period (cotton1:
  eps 9e-6 cm, fiber radius 8e-4 cm). The offset is along the ray, so a ray leaving a surface at a grazing angle
  can still hit it again (a small fraction of uniformly random outward rays, more for a smaller ``eps``:
  BENCHMARKS.md, section "Tessellation, Embree build and ray throughput on one period"); a path tracer should also
  move its spawn points off the surface along the normal.
* Normals are the unit geometric normals of the hit triangles, outward for TubeMesh tubes (not flipped toward the
  ray). Barycentrics follow Embree: hit = (1 - u - v) v0 + u v1 + v v2.
* The scene is committed (BVH built) in the constructor by one single-ray query, never lazily from two threads.
  Batches over ``chunk`` rays are split and run on ``threads`` Python threads (embreex releases the GIL during
  traversal); each ray is independent, so results do not depend on the thread count.
"""

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from embreex.mesh_construction import TriangleMesh
from embreex.rtcore_scene import EmbreeScene

from knitbake.fibers.tessellate import TubeMesh

EPS_REL = 1e-5
NO_HIT_T = 1e37  # embreex's tfar on a miss


@dataclass
class RayHits:
    """First hits of a batch of N rays; misses have t = inf, prim = fiber = -1, normal = u = v = 0."""

    t: np.ndarray  # (N,) float64, distance from the origin
    prim: np.ndarray  # (N,) int32, triangle index
    fiber: np.ndarray  # (N,) int32, fiber index (TubeMesh.tri_fiber of prim)
    normal: np.ndarray  # (N, 3) float64, unit geometric normal
    u: np.ndarray  # (N,) float64, barycentric
    v: np.ndarray  # (N,) float64, barycentric

    @property
    def hit(self) -> np.ndarray:
        return self.prim >= 0


class RayScene:
    """One Embree scene over a TubeMesh (see module docstring)."""

    def __init__(self, mesh: TubeMesh, eps: float | None = None, threads: int = 2, chunk: int = 65536):
        vertices = np.ascontiguousarray(mesh.vertices, dtype=np.float32)
        triangles = np.ascontiguousarray(mesh.triangles, dtype=np.int32)
        if vertices.ndim != 2 or vertices.shape[1] != 3 or triangles.ndim != 2 or triangles.shape[1] != 3:
            raise ValueError(f"mesh needs (V, 3) vertices and (T, 3) triangles, got {vertices.shape}, "
                             f"{triangles.shape}")
        if triangles.shape[0] == 0:
            raise ValueError("mesh has no triangles")
        if not np.all(np.isfinite(vertices)):
            raise ValueError("mesh has non-finite vertices")
        if triangles.min() < 0 or triangles.max() >= vertices.shape[0]:
            raise ValueError(f"mesh triangle indices out of range [0, {vertices.shape[0]})")
        if np.shape(mesh.tri_fiber) != triangles.shape[:1]:
            raise ValueError(f"mesh tri_fiber must have shape ({triangles.shape[0]},), got {np.shape(mesh.tri_fiber)}")
        if eps is None:
            lo, hi = vertices.min(axis=0).astype(np.float64), vertices.max(axis=0).astype(np.float64)
            eps = EPS_REL * max(np.linalg.norm(hi - lo), np.abs(vertices).max())
        if not (np.isfinite(eps) and eps > 0):
            raise ValueError(f"eps must be finite and > 0, got {eps}")
        if threads < 1 or chunk < 1:
            raise ValueError(f"threads and chunk must be >= 1, got {threads}, {chunk}")
        self.eps = float(eps)
        self.threads = int(threads)
        self.chunk = int(chunk)
        self.tri_fiber = np.ascontiguousarray(mesh.tri_fiber, dtype=np.int32)
        self._scene = EmbreeScene()
        self._mesh = TriangleMesh(self._scene, vertices, triangles)  # copies into Embree's buffers
        self._scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32))  # commit: builds the BVH

    def intersect(self, origins, directions, tmax=np.inf) -> RayHits:
        """First hit of each ray within distance (eps, tmax]; tmax is a scalar or (N,)."""
        org, dirs, tmax = self._validated(origins, directions, tmax)
        n = org.shape[0]
        hits = RayHits(t=np.empty(n), prim=np.empty(n, np.int32), fiber=np.empty(n, np.int32),
                       normal=np.empty((n, 3)), u=np.empty(n), v=np.empty(n))

        def run(s):
            out = self._scene.run(*self._embree_rays(org[s], dirs[s], tmax[s]), output=1)
            hit = out["primID"] >= 0
            prim = np.where(hit, out["primID"], -1)
            normal = out["Ng"].astype(np.float64)
            normal[hit] /= np.linalg.norm(normal[hit], axis=1, keepdims=True)
            normal[~hit] = 0.0
            hits.t[s] = np.where(hit, out["tfar"].astype(np.float64) + self.eps, np.inf)
            hits.prim[s] = prim
            hits.fiber[s] = np.where(hit, self.tri_fiber[np.maximum(prim, 0)], -1)
            hits.normal[s] = normal
            hits.u[s] = np.where(hit, out["u"], 0.0)
            hits.v[s] = np.where(hit, out["v"], 0.0)

        self._map(run, n)
        return hits

    def occluded(self, origins, directions, tmax) -> np.ndarray:
        """(N,) bool: whether anything lies on each ray within distance (eps, tmax]; tmax is a scalar or (N,)."""
        org, dirs, tmax = self._validated(origins, directions, tmax)
        blocked = np.empty(org.shape[0], np.bool_)

        def run(s):
            blocked[s] = self._scene.run(*self._embree_rays(org[s], dirs[s], tmax[s]), query="OCCLUDED") >= 0

        self._map(run, org.shape[0])
        return blocked

    def _embree_rays(self, org, dirs, tmax):
        """float32 origins moved by eps along the directions, directions, and tfar (distances from the new origins)."""
        return ((org + self.eps * dirs).astype(np.float32), dirs.astype(np.float32),
                np.minimum(tmax - self.eps, NO_HIT_T).astype(np.float32))

    def _validated(self, origins, directions, tmax):
        """float64 (N, 3) origins, (N, 3) unit directions and (N,) tmax."""
        org = _float_array(origins, "origins")
        dirs = _float_array(directions, "directions")
        if org.ndim != 2 or org.shape[1] != 3 or dirs.shape != org.shape:
            raise ValueError(f"origins and directions must both have shape (N, 3), got {org.shape}, {dirs.shape}")
        for name, a in (("origins", org), ("directions", dirs)):
            bad = ~np.all(np.isfinite(a), axis=1)
            if np.any(bad):
                i = int(np.argmax(bad))
                raise ValueError(f"{name}[{i}] = {a[i].tolist()} is not finite")
        length = np.sqrt(np.einsum("ij,ij->i", dirs, dirs))
        if not np.all(length > 0):
            raise ValueError(f"directions[{int(np.argmin(length > 0))}] is zero")
        tmax = _float_array(tmax, "tmax")
        if tmax.ndim > 1 or tmax.size not in (1, org.shape[0]):
            raise ValueError(f"tmax must be a scalar or have shape ({org.shape[0]},), got {tmax.shape}")
        if np.any(np.isnan(tmax)) or np.any(tmax <= 0):
            raise ValueError("tmax must be > 0 (inf allowed)")
        return org, dirs / length[:, None], np.broadcast_to(tmax, org.shape[:1])

    def _map(self, run, n):
        """Apply run to consecutive slices of at most chunk rays, on up to threads threads."""
        slices = [slice(a, min(a + self.chunk, n)) for a in range(0, n, self.chunk)]
        if self.threads == 1 or len(slices) <= 1:
            for s in slices:
                run(s)
            return
        with ThreadPoolExecutor(self.threads) as pool:
            for _ in pool.map(run, slices):
                pass


def _float_array(a, name) -> np.ndarray:
    try:
        return np.asarray(a, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{name} must be numeric: {e}") from None
