"""Complete model point clouds rendered from a tessellated sphere of views (paper 1's data).

Paper 1 (§3, scenarios 3–7) turned each CAD mesh into ONE complete model point cloud with PCL's
``render_views_tesselated_sphere`` (A. Aldoma, 800 views, the views merged) and then selected
the points visible from each sensor pose by hidden point removal. :func:`model_cloud_for`
does the same with the float64 ray caster of :mod:`relnav.sim.raycast`:

1. ``n_views`` viewpoints spread evenly on a sphere of radius ``distance_factor ·ρ`` around
   the target's bounding sphere (centre ``c``, radius ``ρ``) — a Fibonacci lattice, randomly
   rotated by ``seed`` **[interpretation: PCL subdivides an icosahedron; a Fibonacci lattice
   gives any view count, 800 included, with the same near-uniform spacing]**;
2. per view, a ``resolution × resolution`` pinhole depth image whose field of view just holds
   the bounding sphere (first hits only: each view sees its visible surface), pixel grid rolled
   about the boresight by a seeded random angle;
3. the views' points merged in the target frame (face index kept for each point);
4. optionally thinned (``thinning``): ``"random"`` keeps a seeded random subset of ``size``
   points (nested: a larger size keeps a superset), ``"voxel"`` one point per occupied voxel
   of edge ``voxel``, the one nearest the voxel centroid (as
   :func:`relnav.features.keypoints.voxel_keypoints`, with a 1-D voxel key so that millions
   of merged points are thinned in a fraction of a second), ``"none"`` keeps every point.
   **[interpretation]** Paper 1 does not say how its merged clouds were thinned. The voxel
   grid leaves a regular lattice on flat faces, on which point-to-point ICP locks at lattice
   offsets (measured on sim-voyager, voxel 0.25 m: the first 11 steps each off by 0.8 m,
   T_error 4.8 %); random thinning keeps the merged views' own irregular sampling, so it is
   the sensors' default.

The merged views and the thinned clouds are cached in memory, keyed by the mesh's content and every
parameter (the seed included), so the same target, parameters and seed give the same cloud.
"""

from __future__ import annotations

import hashlib
import logging
import math
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from relnav.errors import ConfigError, InputError
from relnav.sim.targets import Target

__all__ = [
    "ModelCloud",
    "fibonacci_sphere",
    "merged_views",
    "mesh_fingerprint",
    "model_cloud_for",
    "render_views",
    "voxel_representatives",
]

log = logging.getLogger(__name__)

_CACHE: OrderedDict[tuple, ModelCloud] = OrderedDict()
_CACHE_SIZE = 16
_RAW: OrderedDict[tuple, tuple[np.ndarray, np.ndarray]] = OrderedDict()
_RAW_SIZE = 2


@dataclass(frozen=True)
class ModelCloud:
    """A complete model point cloud of a target.

    Attributes
    ----------
    points : (N, 3) float64
        Points on the mesh, target frame, metres (read-only array).
    faces : (N,) int64
        Mesh face of each point.
    thinning : str
        ``"random"``, ``"voxel"`` or ``"none"``.
    param : float
        Random: the requested size; voxel: the voxel edge (m); none: 0.
    n_views : int
        Number of rendered views.
    """

    points: np.ndarray
    faces: np.ndarray
    thinning: str
    param: float
    n_views: int


def fibonacci_sphere(n: int) -> np.ndarray:
    """``n`` unit vectors spread near-uniformly on the sphere (Fibonacci lattice), (n, 3)."""
    k = np.arange(n, dtype=np.float64) + 0.5
    z = 1.0 - 2.0 * k / n
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = math.pi * (3.0 - math.sqrt(5.0)) * k
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def voxel_representatives(points: np.ndarray, voxel: float) -> np.ndarray:
    """Sorted indices (int64) of the point nearest each occupied voxel's centroid.

    Voxel cells ``floor((p − min p) / voxel)``; ties broken by the lower index.
    """
    P = np.asarray(points, dtype=np.float64)
    if P.shape[0] == 0:
        return np.zeros(0, dtype=np.int64)
    lo = P.min(axis=0)
    ijk = np.floor((P - lo) / voxel).astype(np.int64)
    dims = ijk.max(axis=0) + 1
    key = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    _, inv = np.unique(key, return_inverse=True)
    inv = inv.reshape(-1)
    M = int(inv.max()) + 1
    counts = np.bincount(inv, minlength=M).astype(np.float64)
    cen = np.stack([np.bincount(inv, weights=P[:, a], minlength=M) for a in range(3)], 1)
    cen /= counts[:, None]
    d2 = np.sum((P - cen[inv]) ** 2, axis=1)
    order = np.lexsort((np.arange(P.shape[0]), d2, inv))
    first = np.ones(order.size, dtype=bool)
    first[1:] = inv[order[1:]] != inv[order[:-1]]
    return np.sort(order[first]).astype(np.int64)


def _view_basis(d: np.ndarray, roll: float) -> np.ndarray:
    """3×3 rotation whose first column is the boresight ``d`` (unit), rolled by ``roll`` rad."""
    up = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    y = np.cross(up, d)
    y /= np.linalg.norm(y)
    z = np.cross(d, y)
    c, s = math.cos(roll), math.sin(roll)
    return np.stack([d, c * y + s * z, -s * y + c * z], axis=1)


def render_views(
    target: Target,
    n_views: int = 800,
    resolution: int = 64,
    distance_factor: float = 3.0,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """Merged first-hit points of ``n_views`` depth images around ``target`` (no thinning).

    Returns
    -------
    points : (M, 3) float64
        Target frame, metres.
    faces : (M,) int64
        Mesh face of each point.
    """
    rng = np.random.default_rng(seed)
    c, rho = target.bounding_sphere
    D = distance_factor * rho
    half = math.asin(min(1.0, 1.0 / distance_factor))
    tg = math.tan(half)
    u = tg * (1.0 - 2.0 * (np.arange(resolution) + 0.5) / resolution)
    Z, Y = np.meshgrid(u, u, indexing="ij")
    grid = np.stack([np.ones(Y.size), Y.ravel(), Z.ravel()], axis=1)
    grid /= np.linalg.norm(grid, axis=1, keepdims=True)
    R0 = Rotation.random(random_state=rng).as_matrix()
    dirs = fibonacci_sphere(n_views) @ R0.T
    rolls = rng.uniform(0.0, 2.0 * math.pi, n_views)
    rc = target.raycaster
    pts, fcs = [], []
    chunk = max(1, 2_000_000 // grid.shape[0])
    for s in range(0, n_views, chunk):
        o_list, d_list = [], []
        for v in range(s, min(n_views, s + chunk)):
            B = _view_basis(-dirs[v], rolls[v])
            o_list.append(np.broadcast_to(c + D * dirs[v], grid.shape))
            d_list.append(grid @ B.T)
        o = np.ascontiguousarray(np.concatenate(o_list))
        d = np.ascontiguousarray(np.concatenate(d_list))
        r, f = rc.cast(o, d)
        hit = f >= 0
        pts.append(o[hit] + d[hit] * r[hit, None])
        fcs.append(f[hit].astype(np.int64))
    return np.concatenate(pts), np.concatenate(fcs)


def _check(n_views: int, resolution: int, distance_factor: float) -> None:
    if not (isinstance(n_views, int | np.integer) and n_views >= 1):
        raise ConfigError(f"model_views must be a positive integer, got {n_views!r}")
    if not (isinstance(resolution, int | np.integer) and 2 <= resolution <= 4096):
        raise ConfigError(f"model_resolution must be an integer in [2, 4096], got {resolution!r}")
    if not (math.isfinite(distance_factor) and distance_factor > 1):
        raise ConfigError(f"view distance factor must be > 1, got {distance_factor!r}")


def mesh_fingerprint(target: Target) -> str:
    """SHA-1 of the mesh's vertices and faces (content key of the caches)."""
    key = ("model_cloud.fingerprint", id(target.mesh))
    fp = target.cache.get(key)
    if fp is None:
        h = hashlib.sha1()
        h.update(np.ascontiguousarray(target.mesh.vertices, dtype=np.float64).tobytes())
        h.update(np.ascontiguousarray(target.mesh.faces, dtype=np.int64).tobytes())
        fp = h.hexdigest()
        target.cache[key] = fp
    return fp


def merged_views(
    target: Target,
    *,
    n_views: int = 800,
    resolution: int = 64,
    distance_factor: float = 3.0,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`render_views`, cached in memory by mesh content and parameters (read-only)."""
    _check(n_views, resolution, distance_factor)
    key = (mesh_fingerprint(target), int(n_views), int(resolution), float(distance_factor),
           int(seed))  # fmt: skip
    out = _RAW.get(key)
    if out is None:
        P, F = render_views(target, int(n_views), int(resolution), distance_factor, int(seed))
        if P.shape[0] == 0:
            raise InputError(f"target {target.name!r}: no view of the model cloud hit the mesh")
        P.setflags(write=False)
        F.setflags(write=False)
        out = (P, F)
        _RAW[key] = out
        while len(_RAW) > _RAW_SIZE:
            _RAW.popitem(last=False)
    else:
        _RAW.move_to_end(key)
    return out


def model_cloud_for(
    target: Target,
    *,
    n_views: int = 800,
    resolution: int = 64,
    thinning: str = "none",
    size: int = 0,
    voxel: float = 0.0,
    distance_factor: float = 3.0,
    seed: int = 0,
) -> ModelCloud:
    """The model cloud of ``target`` (see the module), cached in memory.

    Parameters
    ----------
    target : Target
        Target (mesh in the target frame).
    n_views : int
        Viewpoints on the tessellated sphere (paper 1: 800).
    resolution : int
        Pixels per side of each view's depth image **[interpretation; PCL's default is 150]**.
    thinning : {"none", "random", "voxel"}
        How the merged views are thinned.
    size : int
        ``random``: points kept (all if larger than the merged cloud).
    voxel : float
        ``voxel``: voxel edge, metres (> 0).
    distance_factor : float
        View-sphere radius over the target's bounding radius (> 1).
    seed : int
        Seed of the view sphere's rotation, the pixel grids' rolls and the random subset.

    Raises
    ------
    ConfigError
        Bad parameters.
    InputError
        The views see nothing (degenerate mesh).
    """
    _check(n_views, resolution, distance_factor)
    if thinning == "random":
        if not (isinstance(size, int | np.integer) and size >= 1):
            raise ConfigError(f"model cloud: random thinning needs size >= 1, got {size!r}")
        param = float(size)
    elif thinning == "voxel":
        if not (math.isfinite(voxel) and voxel > 0):
            raise ConfigError(f"model_voxel must be a positive length (m), got {voxel!r}")
        param = float(voxel)
    elif thinning == "none":
        param = 0.0
    else:
        raise ConfigError(f"model_thinning must be random, voxel or none, got {thinning!r}")
    key = (mesh_fingerprint(target), int(n_views), int(resolution), thinning, param,
           float(distance_factor), int(seed))  # fmt: skip
    mc = _CACHE.get(key)
    if mc is None:
        P, F = merged_views(
            target,
            n_views=n_views,
            resolution=resolution,
            distance_factor=distance_factor,
            seed=seed,
        )
        keep = None
        if thinning == "voxel":
            keep = voxel_representatives(P, voxel)
        elif thinning == "random" and size < P.shape[0]:
            order = _permutation(P.shape[0], seed)
            keep = np.sort(order[: int(size)])
        if keep is not None:
            P, F = P[keep], F[keep]
            P.setflags(write=False)
            F.setflags(write=False)
        mc = ModelCloud(P, F, thinning, param, int(n_views))
        _CACHE[key] = mc
        while len(_CACHE) > _CACHE_SIZE:
            _CACHE.popitem(last=False)
        log.debug("model cloud of %s: %d views, %d points (%s %.4g)",
                  target.name, n_views, P.shape[0], thinning, param)  # fmt: skip
    else:
        _CACHE.move_to_end(key)
    return mc


def _permutation(n: int, seed: int) -> np.ndarray:
    """Seeded permutation of ``range(n)`` (its prefixes are the nested random subsets)."""
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 1]))
    return rng.permutation(n)
