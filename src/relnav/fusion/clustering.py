"""Paper 2's plane clustering after fusion: shape factors, plane/line growing, projection (§G.4).

After cross-source registration the LIDAR points, now in the camera frame, scatter around the
camera's surfaces ("point cloud diffusion"). Paper 2 removes the scatter by snapping each LIDAR
point onto the nearest plane (or line) grown from the dense camera cloud, or discarding it.

1. **Shape factors** per camera point (Westin measures; eigenvalues ``d1 ≥ d2 ≥ d3`` of the
   covariance of its ``k`` nearest neighbours, ``k = 20`` **[interpretation]**,
   ``d = d1 + d2 + d3``): ``F_L = (d1 − d2)/d``, ``F_H = 2(d2 − d3)/d``, ``F_S = 3 d3/d``
   (they sum to 1). Label **[interpretation: "much larger" = factor 2]**: linear if
   ``F_L > 2·max(F_H, F_S)``, planar if ``F_H > 2·max(F_L, F_S)``, edge if ``F_L`` and ``F_H``
   both exceed ``F_S`` without either dominating, else spherical (ignored, as in paper 2).
2. **Plane growing** over planar points: seed = most planar unassigned point; breadth-first
   over the k-NN graph, a planar neighbour joins when its normal is within ``plane_angle_deg``
   (10°) of the region's plane and it lies within ``plane_dist`` of it; the plane is refitted by
   PCA each time the region doubles and at the end (``H = n + d e∞``, ``n·x = d``). Regions
   smaller than ``min_points`` are dropped. **[interpretation]** ``plane_dist`` defaults to
   ``max(2·Tr_K, 3·σ̂)`` with ``σ̂`` = median ``sqrt(d3)`` (local depth noise of the camera,
   which at a few metres exceeds twice the point spacing; ALGORITHMS' 2·Tr_K is
   ``plane_dist_mode="resolution"``).
3. **Line growing** the same way over linear points: direction (eigenvector of ``d1``) within
   ``plane_angle_deg`` of the line's, distance to the line below ``plane_dist``
   (``L = p1 ∧ p2 ∧ e∞``: stored as a point and a unit direction).
4. **LIDAR points** (already in the camera frame) get PCA normals from their own ``lidar_k``
   (20 **[interpretation]**: 10 neighbours lie on one or two scan lines, too few for a normal)
   neighbours. The nearest plane/line is the segment, among those of the ``n_nearest`` (8)
   nearest labelled camera points, with the smallest orthogonal distance; **[interpretation]**
   segments are finite — one whose nearest member point is farther than
   ``max(δ, 2·plane_dist) + 2·plane_dist`` does not count (a point beyond a face's edge is not
   snapped onto its infinite plane). A point is kept if
   ``arccos(|n_i·n_j|) ≤ σ = 45°`` (planes; for lines the LIDAR normal must be within ``σ`` of
   perpendicular to the line, **[interpretation]**) **and** its distance is ``≤ δ``; a LIDAR
   neighbourhood that is itself collinear (scan line, ``F_L > 0.8``) has no defined normal and
   skips the angle test **[interpretation]**. ``δ`` (``delta="parallel-planes"``, ALGORITHMS):
   twice the smallest distance between two parallel (≤ ``plane_angle_deg``) planes of the camera
   model farther apart than ``plane_dist``; fallback ``2·Tr_K``. ``delta="resolution"``:
   ``2·Tr_K``; a number: metres.
5. Kept points are replaced by their orthogonal projection (paper 2 eq. 26 — right angle and
   ``(p_j ∧ p0 ∧ e∞)·H = 0`` — is exactly that): plane ``p0 = p − (n·p − d) n``, line
   ``p0 = a + ((p − a)·u) u``.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from scipy.spatial import cKDTree

from relnav.errors import ConfigError, InputError
from relnav.geometry.neighbors import mean_resolution

__all__ = [
    "ClusterResult",
    "Line",
    "Plane",
    "ShapeFactors",
    "cluster_and_project",
    "grow_lines",
    "grow_planes",
    "shape_factors",
]

log = logging.getLogger(__name__)

SPHERICAL, LINEAR, PLANAR, EDGE = 0, 1, 2, 3
"""Shape labels of :func:`shape_factors`."""


@dataclass(frozen=True)
class ShapeFactors:
    """Per-point shape analysis of a cloud.

    Attributes
    ----------
    F_L, F_H, F_S : (N,) float64
        Linear, planar ("H") and spherical shape factors (sum to 1; NaN if undefined).
    labels : (N,) int8
        ``0`` spherical/undefined, ``1`` linear, ``2`` planar, ``3`` edge.
    normals : (N, 3) float64
        Eigenvector of the smallest eigenvalue (unit, unoriented).
    directions : (N, 3) float64
        Eigenvector of the largest eigenvalue (unit, unoriented).
    sqrt_d3 : (N,) float64
        ``sqrt`` of the smallest eigenvalue (m): local out-of-plane spread.
    """

    F_L: np.ndarray
    F_H: np.ndarray
    F_S: np.ndarray
    labels: np.ndarray
    normals: np.ndarray
    directions: np.ndarray
    sqrt_d3: np.ndarray


@dataclass(frozen=True)
class Plane:
    """A plane grown from camera points: ``n·x = d`` (``π = n + d e∞`` in CGA).

    Attributes
    ----------
    normal : (3,) float64
        Unit normal.
    d : float
        Signed distance of the plane from the origin (m).
    centroid : (3,) float64
        Mean of the member points (m).
    indices : (K,) int64
        Member camera-point indices.
    """

    normal: np.ndarray
    d: float
    centroid: np.ndarray
    indices: np.ndarray

    @property
    def n_points(self) -> int:
        """Number of member points."""
        return int(self.indices.size)

    def cga(self) -> np.ndarray:
        """IPNS plane ``n + d e∞`` as ``(5,)`` coefficients (see :mod:`relnav.geometry.cga`)."""
        from relnav.geometry.cga import plane_vectors

        return plane_vectors(self.normal, self.d)


@dataclass(frozen=True)
class Line:
    """A line grown from camera points: ``a + s u`` (``L = p1 ∧ p2 ∧ e∞`` in CGA).

    Attributes
    ----------
    point : (3,) float64
        A point on the line (centroid of the members, m).
    direction : (3,) float64
        Unit direction.
    indices : (K,) int64
        Member camera-point indices.
    """

    point: np.ndarray
    direction: np.ndarray
    indices: np.ndarray

    @property
    def n_points(self) -> int:
        """Number of member points."""
        return int(self.indices.size)


@dataclass
class ClusterResult:
    """Output of :func:`cluster_and_project` (also unpackable as a 4-tuple).

    Attributes
    ----------
    fused_points : (M + K, 3) float64
        Camera points followed by the ``K`` kept, projected LIDAR points (camera frame).
    kept_mask : (N,) bool
        Which LIDAR points were kept.
    planes, lines : list
        The camera model's :class:`Plane` and :class:`Line` segments.
    projected : (N, 3) float64
        Projection of every LIDAR point (NaN where removed).
    segment : (N,) int64
        Index of the segment each LIDAR point was projected on: planes ``0 … P−1``, lines
        ``P …``; ``-1`` if removed.
    delta : float
        Distance gate used (m).
    info : dict
        Counts and parameters.
    """

    fused_points: np.ndarray
    kept_mask: np.ndarray
    planes: list[Plane]
    lines: list[Line]
    projected: np.ndarray
    segment: np.ndarray
    delta: float
    info: dict[str, Any] = field(default_factory=dict)

    def __iter__(self) -> Any:
        return iter((self.fused_points, self.kept_mask, self.planes, self.lines))


# --------------------------------------------------------------------------------------------


def _as_points(points: Any, name: str) -> np.ndarray:
    P = np.asarray(points, dtype=np.float64)
    if P.size == 0:
        return np.zeros((0, 3))
    if P.ndim != 2 or P.shape[1] != 3:
        raise InputError(f"{name}: expected an (N, 3) array, got shape {P.shape}")
    if not np.isfinite(P).all():
        raise InputError(f"{name}: non-finite coordinates")
    return P


def _knn(P: np.ndarray, k: int, tree: cKDTree | None = None) -> np.ndarray:
    tree = tree if tree is not None else cKDTree(P)
    kk = int(min(k, P.shape[0]))
    _, idx = tree.query(P, k=kk)
    return idx.reshape(P.shape[0], kk)


def _eig_knn(P: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    nb = P[idx]
    d = nb - nb.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", d, d) / idx.shape[1]
    w, v = np.linalg.eigh(cov)  # ascending
    return np.maximum(w, 0.0), v


def shape_factors(
    points: np.ndarray, *, k: int = 20, dominance: float = 2.0, knn_idx: np.ndarray | None = None
) -> ShapeFactors:
    """Shape factors ``F_L, F_H, F_S`` and labels of every point (paper 2 eq. 22).

    Parameters
    ----------
    points : (N, 3) float64
        Cloud (m).
    k : int
        Neighbourhood size (including the point).
    dominance : float
        "Much larger" factor of the labelling rule.
    knn_idx : (N, k) int64, optional
        Precomputed neighbour indices.
    """
    P = _as_points(points, "points")
    n = P.shape[0]
    nan = np.full(n, np.nan)
    if n < 3:
        z = np.full((n, 3), np.nan)
        return ShapeFactors(nan, nan, nan, np.zeros(n, np.int8), z, z.copy(), nan)
    idx = knn_idx if knn_idx is not None else _knn(P, k)
    w, v = _eig_knn(P, idx)
    d3, d2, d1 = w[:, 0], w[:, 1], w[:, 2]
    d = d1 + d2 + d3
    with np.errstate(invalid="ignore", divide="ignore"):
        FL = (d1 - d2) / d
        FH = 2.0 * (d2 - d3) / d
        FS = 3.0 * d3 / d
    labels = np.zeros(n, dtype=np.int8)
    a = dominance
    lin = FL > a * np.maximum(FH, FS)
    pla = FH > a * np.maximum(FL, FS)
    edge = ~lin & ~pla & (FL > FS) & (FH > FS)
    labels[lin] = LINEAR
    labels[pla] = PLANAR
    labels[edge] = EDGE
    return ShapeFactors(FL, FH, FS, labels, v[:, :, 0], v[:, :, 2], np.sqrt(d3))


def _fit_plane(X: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
    c = X.mean(axis=0)
    _, v = np.linalg.eigh((X - c).T @ (X - c))
    n = v[:, 0]
    return n, float(n @ c), c


def _fit_line(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    c = X.mean(axis=0)
    _, v = np.linalg.eigh((X - c).T @ (X - c))
    return c, v[:, 2]


def _grow(
    P: np.ndarray,
    knn_idx: np.ndarray,
    eligible: np.ndarray,
    order: np.ndarray,
    axes: np.ndarray,
    kind: Literal["plane", "line"],
    cos_tol: float,
    dist: float,
    min_points: int,
) -> tuple[list[np.ndarray], list[tuple[np.ndarray, Any]]]:
    """Region growing shared by planes and lines; returns member lists and fitted models."""
    n = P.shape[0]
    assigned = np.zeros(n, dtype=bool)
    regions: list[np.ndarray] = []
    models: list[tuple[np.ndarray, Any]] = []
    for s in order:
        if assigned[s] or not eligible[s]:
            continue
        members = [np.array([s])]
        in_region = np.zeros(n, dtype=bool)
        in_region[s] = True
        size = 1
        axis = axes[s]
        origin = P[s].copy()
        frontier = np.array([s])
        next_refit = 8
        while frontier.size:
            nb = np.unique(knn_idx[frontier].ravel())
            nb = nb[eligible[nb] & ~assigned[nb] & ~in_region[nb]]
            if nb.size == 0:
                break
            if kind == "plane":
                ok = np.abs(axes[nb] @ axis) >= cos_tol
                ok &= np.abs((P[nb] - origin) @ axis) < dist
            else:
                ok = np.abs(axes[nb] @ axis) >= cos_tol
                r = P[nb] - origin
                ok &= np.linalg.norm(r - np.outer(r @ axis, axis), axis=1) < dist
            nb = nb[ok]
            if nb.size == 0:
                break
            in_region[nb] = True
            members.append(nb)
            size += nb.size
            frontier = nb
            if size >= next_refit:
                X = P[in_region]
                if kind == "plane":
                    axis, _, origin = _fit_plane(X)
                else:
                    origin, axis = _fit_line(X)
                next_refit = 2 * size
        if size < min_points:
            continue
        idx = np.sort(np.concatenate(members))
        assigned[idx] = True
        X = P[idx]
        if kind == "plane":
            nrm, d, c = _fit_plane(X)
            models.append((nrm, (d, c)))
        else:
            c, u = _fit_line(X)
            models.append((u, c))
        regions.append(idx)
    return regions, models


def grow_planes(
    points: np.ndarray,
    sf: ShapeFactors,
    *,
    knn_idx: np.ndarray,
    angle_deg: float = 10.0,
    dist: float,
    min_points: int = 15,
) -> list[Plane]:
    """Planes grown over the planar points of ``sf`` (see the module docstring, step 2)."""
    P = _as_points(points, "points")
    eligible = sf.labels == PLANAR
    order = np.argsort(-np.nan_to_num(sf.F_H, nan=-1.0), kind="stable")
    regions, models = _grow(
        P,
        knn_idx,
        eligible,
        order,
        sf.normals,
        "plane",
        math.cos(math.radians(angle_deg)),
        dist,
        min_points,
    )
    return [
        Plane(normal=n, d=float(dc[0]), centroid=dc[1], indices=idx)
        for (n, dc), idx in zip(models, regions, strict=True)
    ]


def grow_lines(
    points: np.ndarray,
    sf: ShapeFactors,
    *,
    knn_idx: np.ndarray,
    angle_deg: float = 10.0,
    dist: float,
    min_points: int = 10,
) -> list[Line]:
    """Lines grown over the linear points of ``sf`` (see the module docstring, step 3)."""
    P = _as_points(points, "points")
    eligible = sf.labels == LINEAR
    order = np.argsort(-np.nan_to_num(sf.F_L, nan=-1.0), kind="stable")
    regions, models = _grow(
        P,
        knn_idx,
        eligible,
        order,
        sf.directions,
        "line",
        math.cos(math.radians(angle_deg)),
        dist,
        min_points,
    )
    return [
        Line(point=c, direction=u, indices=idx) for (u, c), idx in zip(models, regions, strict=True)
    ]


def _parallel_plane_delta(planes: list[Plane], cos_tol: float, min_sep: float) -> float | None:
    best = math.inf
    for i in range(len(planes)):
        for j in range(i + 1, len(planes)):
            c = float(planes[i].normal @ planes[j].normal)
            if abs(c) < cos_tol:
                continue
            sep = abs(planes[j].d - math.copysign(1.0, c) * planes[i].d)
            if sep > min_sep:
                best = min(best, sep)
    return None if not math.isfinite(best) else 2.0 * best


def cluster_and_project(
    camera_pts: np.ndarray,
    lidar_pts_in_camera_frame: np.ndarray,
    *,
    k: int = 20,
    dominance: float = 2.0,
    plane_angle_deg: float = 10.0,
    plane_dist: float | None = None,
    plane_dist_mode: Literal["noise", "resolution"] = "noise",
    min_plane_points: int = 15,
    min_line_points: int = 10,
    sigma_deg: float = 45.0,
    delta: float | Literal["parallel-planes", "resolution"] = "parallel-planes",
    lidar_k: int = 20,
    n_nearest: int = 8,
    use_lines: bool = True,
) -> ClusterResult:
    """Cluster the camera cloud into planes/lines and snap the LIDAR points onto them.

    Parameters
    ----------
    camera_pts : (M, 3) float64
        Dense camera cloud, camera frame (m).
    lidar_pts_in_camera_frame : (N, 3) float64
        Registered LIDAR points, camera frame (m).
    k : int
        Neighbourhood size of the camera shape factors.
    dominance : float
        "Much larger" factor of the shape labels.
    plane_angle_deg : float
        Normal/direction tolerance of plane/line growing (degrees).
    plane_dist : float, optional
        Distance tolerance of growing (m); default from ``plane_dist_mode``.
    plane_dist_mode : {"noise", "resolution"}
        ``max(2·Tr_K, 3·σ̂)`` or ``2·Tr_K`` (module docstring).
    min_plane_points, min_line_points : int
        Smallest segments kept.
    sigma_deg : float
        Normal-angle threshold σ (paper 2: 45°).
    delta : float or {"parallel-planes", "resolution"}
        Distance threshold δ (module docstring).
    lidar_k : int
        Neighbours of the LIDAR PCA normals.
    n_nearest : int
        Labelled camera points whose segments are candidates for each LIDAR point.
    use_lines : bool
        Also grow and use lines.

    Returns
    -------
    ClusterResult
        Unpacks as ``fused_pts, kept_mask, planes, lines``.

    Raises
    ------
    InputError
        Arrays of the wrong shape or with non-finite values.
    ConfigError
        Invalid parameters.
    """
    C = _as_points(camera_pts, "camera_pts")
    L = _as_points(lidar_pts_in_camera_frame, "lidar_pts_in_camera_frame")
    if not 0 < sigma_deg <= 90:
        raise ConfigError(f"sigma_deg must be in (0, 90], got {sigma_deg}")
    if not 0 < plane_angle_deg < 90:
        raise ConfigError(f"plane_angle_deg must be in (0, 90), got {plane_angle_deg}")
    if int(k) != k or k < 3 or int(lidar_k) != lidar_k or lidar_k < 3:
        raise ConfigError(f"k and lidar_k must be integers >= 3, got {k}, {lidar_k}")
    if plane_dist_mode not in ("noise", "resolution"):
        raise ConfigError(f"plane_dist_mode must be 'noise' or 'resolution', got {plane_dist_mode}")
    n_l = L.shape[0]
    empty = ClusterResult(
        fused_points=C.copy(),
        kept_mask=np.zeros(n_l, dtype=bool),
        planes=[],
        lines=[],
        projected=np.full((n_l, 3), np.nan),
        segment=np.full(n_l, -1, dtype=np.int64),
        delta=float("nan"),
        info={"reason": ""},
    )
    if C.shape[0] < max(k, 4):
        empty.info["reason"] = f"camera cloud too small ({C.shape[0]} points)"
        return empty
    tree_c = cKDTree(C)
    knn_c = _knn(C, k, tree_c)
    sf = shape_factors(C, k=k, dominance=dominance, knn_idx=knn_c)
    tr = mean_resolution(C)
    if plane_dist is None:
        plane_dist = 2.0 * tr
        if plane_dist_mode == "noise":
            plane_dist = max(plane_dist, 3.0 * float(np.nanmedian(sf.sqrt_d3)))
    elif not plane_dist > 0:
        raise ConfigError(f"plane_dist must be > 0, got {plane_dist}")
    planes = grow_planes(
        C,
        sf,
        knn_idx=knn_c,
        angle_deg=plane_angle_deg,
        dist=plane_dist,
        min_points=min_plane_points,
    )
    lines = (
        grow_lines(
            C,
            sf,
            knn_idx=knn_c,
            angle_deg=plane_angle_deg,
            dist=plane_dist,
            min_points=min_line_points,
        )
        if use_lines
        else []
    )
    cos_par = math.cos(math.radians(plane_angle_deg))
    if isinstance(delta, str):
        if delta == "parallel-planes":
            dv = _parallel_plane_delta(planes, cos_par, plane_dist)
            delta_v = dv if dv is not None else 2.0 * tr
        elif delta == "resolution":
            delta_v = 2.0 * tr
        else:
            raise ConfigError(f"delta must be a number, 'parallel-planes' or 'resolution': {delta}")
    else:
        delta_v = float(delta)
        if not delta_v > 0:
            raise ConfigError(f"delta must be > 0, got {delta}")
    info: dict[str, Any] = {
        "n_camera": int(C.shape[0]),
        "n_lidar": n_l,
        "n_planes": len(planes),
        "n_lines": len(lines),
        "plane_dist": plane_dist,
        "resolution_camera": tr,
        "labels": {
            "linear": int(np.sum(sf.labels == LINEAR)),
            "planar": int(np.sum(sf.labels == PLANAR)),
            "edge": int(np.sum(sf.labels == EDGE)),
            "spherical": int(np.sum(sf.labels == SPHERICAL)),
        },
    }
    # segment id per camera point
    seg_of = np.full(C.shape[0], -1, dtype=np.int64)
    for i, pl in enumerate(planes):
        seg_of[pl.indices] = i
    for j, ln in enumerate(lines):
        seg_of[ln.indices] = len(planes) + j
    labelled = np.flatnonzero(seg_of >= 0)
    if n_l == 0 or labelled.size == 0:
        empty.planes, empty.lines, empty.delta = planes, lines, delta_v
        empty.info.update(info, reason="no LIDAR points" if n_l == 0 else "no planes or lines")
        return empty
    seg_n = np.array([pl.normal for pl in planes] + [ln.direction for ln in lines])
    seg_a = np.array([pl.centroid for pl in planes] + [ln.point for ln in lines])
    seg_d = np.array([pl.d for pl in planes] + [0.0] * len(lines))
    is_line = np.array([False] * len(planes) + [True] * len(lines))

    # LIDAR normals
    if n_l >= 3:
        sf_l = shape_factors(L, k=lidar_k)
        n_lid = sf_l.normals
        no_normal = ~(sf_l.F_L <= 0.8)
    else:
        n_lid = np.full((n_l, 3), np.nan)
        no_normal = np.ones(n_l, dtype=bool)
    # candidate segments from the nearest labelled camera points
    kk = int(min(n_nearest, labelled.size))
    d_nn, nn = cKDTree(C[labelled]).query(L, k=kk)
    nn = nn.reshape(n_l, kk)
    d_nn = d_nn.reshape(n_l, kk)
    cand = seg_of[labelled[nn]]  # (N, kk)
    r = L[:, None, :] - seg_a[cand]  # (N, kk, 3)
    u = seg_n[cand]
    along = np.einsum("nki,nki->nk", r, u)
    plane_dist_c = np.abs(np.einsum("nki,nki->nk", L[:, None, :], u) - seg_d[cand])
    line_dist_c = np.linalg.norm(r - along[..., None] * u, axis=2)
    dist_c = np.where(is_line[cand], line_dist_c, plane_dist_c)
    # a segment is a candidate only where it has support: one of its points within the gate
    support = max(delta_v, 2.0 * plane_dist) + 2.0 * plane_dist
    dist_c = np.where(d_nn <= support, dist_c, np.inf)
    best = np.argmin(dist_c, axis=1)
    rows = np.arange(n_l)
    seg = cand[rows, best]
    dist = dist_c[rows, best]
    cosang = np.abs(np.einsum("ni,ni->n", np.nan_to_num(n_lid), seg_n[seg]))
    sin_s = math.sin(math.radians(sigma_deg))
    cos_s = math.cos(math.radians(sigma_deg))
    angle_ok = np.where(is_line[seg], cosang <= sin_s, cosang >= cos_s) | no_normal
    keep = angle_ok & (dist <= delta_v)
    proj = np.full((n_l, 3), np.nan)
    a = seg_a[seg]
    uu = seg_n[seg]
    on_line = is_line[seg]
    pl_proj = L - (np.einsum("ni,ni->n", L, uu) - seg_d[seg])[:, None] * uu
    ln_proj = a + np.einsum("ni,ni->n", L - a, uu)[:, None] * uu
    proj_all = np.where(on_line[:, None], ln_proj, pl_proj)
    proj[keep] = proj_all[keep]
    segment = np.where(keep, seg, -1)
    info.update(
        n_kept=int(keep.sum()),
        n_removed_angle=int(np.sum(~angle_ok)),
        n_removed_distance=int(np.sum(angle_ok & (dist > delta_v))),
        n_no_lidar_normal=int(no_normal.sum()),
    )
    log.debug("cluster_and_project: %s", info)
    return ClusterResult(
        fused_points=np.vstack([C, proj[keep]]),
        kept_mask=keep,
        planes=planes,
        lines=lines,
        projected=proj,
        segment=segment,
        delta=delta_v,
        info=info,
    )
