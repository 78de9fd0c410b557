"""First-hit ray casting against a triangle mesh (Embree through trimesh, float64-exact ranges).

Embree works in float32, so the triangle it reports is correct but its hit distance is only
good to ~1e-7 of the scene size. :class:`RayCaster` therefore re-intersects every reported hit
with its triangle in float64 (Möller–Trumbore). When a float32 hit lands within rounding of a
triangle edge and the float64 test says the ray actually passes through a neighbour, the
triangles sharing a vertex with the reported one are tested too and the nearest float64 hit is
kept. Noiseless hit points therefore lie on the mesh to ~1e-12 of the range.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
import trimesh
from numba import njit

from relnav.errors import InputError

__all__ = ["RayCaster"]

log = logging.getLogger(__name__)

_BARY_EPS = 1e-10  # barycentric tolerance of the float64 triangle test (dimensionless)


@njit(cache=True)
def _moller_trumbore(o, d, v0, e1, e2):  # pragma: no cover - compiled
    """Ray/triangle test in float64: returns (t, u, v, ok) with ok False when parallel."""
    px = d[1] * e2[2] - d[2] * e2[1]
    py = d[2] * e2[0] - d[0] * e2[2]
    pz = d[0] * e2[1] - d[1] * e2[0]
    det = e1[0] * px + e1[1] * py + e1[2] * pz
    scale = np.sqrt(e1[0] ** 2 + e1[1] ** 2 + e1[2] ** 2) * np.sqrt(
        e2[0] ** 2 + e2[1] ** 2 + e2[2] ** 2
    )
    if scale == 0.0 or abs(det) <= 1e-14 * scale:
        return np.inf, -1.0, -1.0, False
    inv = 1.0 / det
    sx = o[0] - v0[0]
    sy = o[1] - v0[1]
    sz = o[2] - v0[2]
    u = (sx * px + sy * py + sz * pz) * inv
    qx = sy * e1[2] - sz * e1[1]
    qy = sz * e1[0] - sx * e1[2]
    qz = sx * e1[1] - sy * e1[0]
    v = (d[0] * qx + d[1] * qy + d[2] * qz) * inv
    t = (e2[0] * qx + e2[1] * qy + e2[2] * qz) * inv
    return t, u, v, True


@njit(cache=True)
def _refine(
    origins, dirs, tri, v0, e1, e2, faces, vf_ptr, vf_idx, ranges, face_out
):  # pragma: no cover - compiled
    """Float64 re-intersection of Embree's first hits (in place into ranges / face_out)."""
    n = origins.shape[0]
    eps = _BARY_EPS
    for i in range(n):
        f = tri[i]
        ranges[i] = np.inf
        face_out[i] = -1
        if f < 0:
            continue
        o = origins[i]
        d = dirs[i]
        t, u, v, ok = _moller_trumbore(o, d, v0[f], e1[f], e2[f])
        if ok and t > 0.0 and u >= -eps and v >= -eps and u + v <= 1.0 + eps:
            ranges[i] = t
            face_out[i] = f
            continue
        # float32 hit near an edge/vertex: test the triangles around the reported one
        best_t = np.inf
        best_f = -1
        for k in range(3):
            vert = faces[f, k]
            for j in range(vf_ptr[vert], vf_ptr[vert + 1]):
                g = vf_idx[j]
                tg, ug, vg, okg = _moller_trumbore(o, d, v0[g], e1[g], e2[g])
                if not okg or tg <= 0.0:
                    continue
                if ug >= -eps and vg >= -eps and ug + vg <= 1.0 + eps and tg < best_t:
                    best_t = tg
                    best_f = g
        if best_f >= 0:
            ranges[i] = best_t
            face_out[i] = best_f
        elif ok and t > 0.0:
            # no float64 containment anywhere nearby: keep the plane hit of Embree's triangle
            ranges[i] = t
            face_out[i] = f


class RayCaster:
    """First-hit ray caster for one triangle mesh.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Target mesh (target frame, metres). Must not be modified while the caster is in use.
    backend : {"auto", "embree", "triangle"}
        ``"auto"`` uses Embree and falls back to trimesh's pure-NumPy triangle intersector
        (``trimesh.ray.ray_triangle``) with a logged warning when embreex is not importable.
        The Embree scene is built with embreex directly, as ``trimesh.ray.ray_pyembree`` does
        (same shift/scale to a 100-unit box), but without that wrapper's per-call float64
        copies and re-normalisation, which cost about twice the Embree query itself.

    Notes
    -----
    Build once per mesh and reuse (building the Embree BVH of a 40k-face mesh takes ~10 ms;
    :class:`relnav.sim.targets.Target` caches one). The caster is picklable: the BVH is
    rebuilt lazily after unpickling.
    """

    def __init__(self, mesh: trimesh.Trimesh, *, backend: str = "auto") -> None:
        if not isinstance(mesh, trimesh.Trimesh):
            raise InputError(f"RayCaster needs a trimesh.Trimesh, got {type(mesh).__name__}")
        if len(mesh.faces) == 0:
            raise InputError("RayCaster: mesh has no faces")
        if backend not in ("auto", "embree", "triangle"):
            raise InputError(f"RayCaster: unknown backend {backend!r} (auto, embree, triangle)")
        self.mesh = mesh
        self._requested_backend = backend
        V = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
        F = np.ascontiguousarray(mesh.faces, dtype=np.int64)
        self._faces = F
        self._v0 = np.ascontiguousarray(V[F[:, 0]])
        self._e1 = np.ascontiguousarray(V[F[:, 1]] - self._v0)
        self._e2 = np.ascontiguousarray(V[F[:, 2]] - self._v0)
        n = np.cross(self._e1, self._e2)
        norm = np.linalg.norm(n, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            self._normals = np.where(norm[:, None] > 0, n / norm[:, None], 0.0)
        # vertex -> faces adjacency in CSR form (for the edge refinement)
        flat = F.ravel()
        order = np.argsort(flat, kind="stable")
        self._vf_idx = (order // 3).astype(np.int64)
        counts = np.bincount(flat, minlength=len(V))
        self._vf_ptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        self._intersector: Any = None
        self._shift = np.zeros(3)
        self._scale = 1.0
        self.backend = ""
        self._build()

    def _build(self) -> None:
        backend = self._requested_backend
        if backend in ("auto", "embree"):
            try:
                from embreex import rtcore_scene
                from embreex.mesh_construction import TriangleMesh

                # Embree is float32: shift/scale the mesh to a ~100-unit box around the
                # origin (as trimesh does) so its internal epsilons behave at any size.
                V = np.asarray(self.mesh.vertices, dtype=np.float64)
                lo, hi = V.min(axis=0), V.max(axis=0)
                self._shift = 0.5 * (lo + hi)
                ext = float(np.max(hi - lo))
                self._scale = 100.0 / ext if ext > 0 else 1.0
                scene = rtcore_scene.EmbreeScene()
                TriangleMesh(
                    scene=scene,
                    vertices=((V - self._shift) * self._scale).astype(np.float32),
                    indices=self._faces.astype(np.int32),
                )
                self._intersector = scene
                self.backend = "embree"
                return
            except ImportError as e:
                if backend == "embree":
                    raise InputError(f"RayCaster: Embree backend unavailable ({e})") from None
                log.warning(
                    "embreex not importable (%s); falling back to trimesh's slow triangle "
                    "intersector (pip install embreex)",
                    e,
                )
        from trimesh.ray.ray_triangle import RayMeshIntersector as Tri

        self._intersector = Tri(self.mesh)
        self.backend = "triangle"

    def _first_faces(self, o: np.ndarray, d: np.ndarray) -> np.ndarray:
        """Index of the first face hit by each ray (-1 on a miss), from the backend."""
        if self.backend == "embree":
            o32 = ((o - self._shift) * self._scale).astype(np.float32)
            return np.asarray(self._intersector.run(o32, d.astype(np.float32)), dtype=np.int64)
        return np.asarray(self._intersector.intersects_first(o, d), dtype=np.int64)

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_intersector"] = None
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._build()

    @property
    def face_normals(self) -> np.ndarray:
        """(F, 3) float64 unit face normals (right-hand winding; zero for degenerate faces)."""
        return self._normals

    def cast(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Cast rays and return the first hit of each.

        Parameters
        ----------
        origins : (R, 3) float64
            Ray origins in the mesh frame, metres.
        directions : (R, 3) float64
            Ray directions in the mesh frame (unit; normalised here if not).

        Returns
        -------
        ranges : (R,) float64
            Distance along each ray to its first hit, metres; ``inf`` on a miss.
        face_index : (R,) int64
            Index of the face hit; ``-1`` on a miss.
        """
        o = np.ascontiguousarray(origins, dtype=np.float64).reshape(-1, 3)
        d = np.ascontiguousarray(directions, dtype=np.float64).reshape(-1, 3)
        if o.shape != d.shape:
            raise InputError(f"RayCaster.cast: origins {o.shape} and directions {d.shape} differ")
        R = o.shape[0]
        ranges = np.full(R, np.inf)
        face = np.full(R, -1, dtype=np.int64)
        if R == 0:
            return ranges, face
        if not (np.isfinite(o).all() and np.isfinite(d).all()):
            raise InputError("RayCaster.cast: non-finite ray origins or directions")
        dn = np.linalg.norm(d, axis=1)
        if np.any(dn == 0.0):
            raise InputError("RayCaster.cast: zero-length ray direction")
        if np.any(np.abs(dn - 1.0) > 1e-12):
            d = d / dn[:, None]
        if self._intersector is None:
            self._build()
        tri = self._first_faces(o, d)
        _refine(
            o,
            d,
            tri,
            self._v0,
            self._e1,
            self._e2,
            self._faces,
            self._vf_ptr,
            self._vf_idx,
            ranges,
            face,
        )
        return ranges, face
